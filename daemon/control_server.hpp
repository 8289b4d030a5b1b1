// The control socket: a ZeroMQ ROUTER that answers every request with exactly one reply.
#pragma once

#include <functional>
#include <string>
#include <zmq.hpp>

#include "plenopiv.pb.h"

namespace plenopiv::daemon {

// Turns a parsed request into its reply. It may throw: InputError is answered INVALID,
// WrongStateError WRONG_STATE, anything else INTERNAL; the server goes on.
using RequestHandler = std::function<msg::Reply(const msg::Request&)>;

// Serves REQ and DEALER clients alike (the envelope is echoed back as it came). A message that is
// not a Request gets an Error MALFORMED reply; the server never stops for a bad client.
class ControlServer {
 public:
  ControlServer(zmq::context_t& context, const std::string& endpoint, RequestHandler handler);

  // Waits up to `timeout_ms` for one request and answers it. Returns true if one was served.
  bool serve_one(int timeout_ms);
  const std::string& endpoint() const { return endpoint_; }

 private:
  zmq::socket_t socket_;
  std::string endpoint_;
  RequestHandler handler_;
};

// An Error reply with a code and message.
msg::Reply error_reply(std::uint64_t id, msg::Error::Code code, const std::string& message);

}  // namespace plenopiv::daemon
