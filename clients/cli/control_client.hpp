// A control connection to plenopivd: one request, one reply, a clear error after a timeout.
#pragma once

#include <chrono>
#include <stdexcept>
#include <string>
#include <zmq.hpp>

#include "plenopiv.pb.h"
#include "proto/curve.hpp"

namespace plenopiv::client {

// The daemon did not answer, or answered with something that is not a Reply.
class ControlError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class ControlClient {
 public:
  // `security`: the server's key and this client's key pair when the daemon's control socket uses
  // CURVE (tcp://); none for its local ipc:// socket.
  explicit ControlClient(std::string endpoint, std::chrono::milliseconds timeout = std::chrono::milliseconds(3000),
                         wire::ClientSecurity security = {});

  // Sends `request` (its id is set here) and waits for the reply. Throws ControlError when no
  // reply arrives within the timeout; never hangs.
  msg::Reply call(msg::Request request);
  const std::string& endpoint() const { return endpoint_; }

 private:
  zmq::context_t context_;
  std::string endpoint_;
  std::chrono::milliseconds timeout_;
  wire::ClientSecurity security_;
  std::uint64_t next_id_ = 1;
};

}  // namespace plenopiv::client
