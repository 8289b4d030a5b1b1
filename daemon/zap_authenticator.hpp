// The ZAP handler (ZeroMQ RFC 27) of plenopivd: admits CURVE clients whose public key is allowed.
#pragma once

#include <atomic>
#include <cstdint>
#include <set>
#include <string>
#include <thread>
#include <zmq.hpp>

namespace plenopiv::daemon {

// Answers the ZAP requests of every socket of `context` on its own thread: a CURVE client is
// admitted when its public key (Z85) is in `allowed_keys`, refused otherwise (and counted); NULL
// connections (ipc:// sockets on this machine, which file permissions guard) are admitted. Create it
// before binding any CURVE socket of the context; it must outlive them.
class ZapAuthenticator {
 public:
  ZapAuthenticator(zmq::context_t& context, std::set<std::string> allowed_keys);
  ~ZapAuthenticator();
  ZapAuthenticator(const ZapAuthenticator&) = delete;
  ZapAuthenticator& operator=(const ZapAuthenticator&) = delete;

  std::uint64_t admitted() const { return admitted_; }
  std::uint64_t refused() const { return refused_; }

 private:
  void serve();

  zmq::socket_t socket_;
  std::set<std::string> allowed_;
  std::atomic<bool> quit_{false};
  std::atomic<std::uint64_t> admitted_{0}, refused_{0};
  std::thread thread_;
};

}  // namespace plenopiv::daemon
