// The control socket: a ZeroMQ ROUTER that answers every request with exactly one reply.
#pragma once

#include <functional>
#include <future>
#include <optional>
#include <string>
#include <variant>
#include <vector>
#include <zmq.hpp>

#include "plenopiv.pb.h"
#include "proto/curve.hpp"

namespace plenopiv::daemon {

// A reply that work off the control thread completes later (device discovery): the server keeps
// serving and sends it when it is ready.
using DeferredReply = std::future<msg::Reply>;
using HandlerResult = std::variant<msg::Reply, DeferredReply>;

// Turns a parsed request into its reply, now or deferred. It may throw (and a deferred reply may
// hold an exception): InputError is answered INVALID, WrongStateError WRONG_STATE, anything else
// INTERNAL; the server goes on.
using RequestHandler = std::function<HandlerResult(const msg::Request&)>;

// Who may talk to the control socket.
struct ControlSecurity {
  // CURVE server keys (the socket then admits only clients the context's ZAP handler allows);
  // empty: no CURVE, which validate() allows on ipc:// only.
  std::optional<wire::CurveCertificate> curve;
  // ipc:// endpoints: the socket file gets mode 0660 (owner and group may connect, no one else) and,
  // when set, this group (e.g. "plenopiv"); its folder is made if missing.
  std::string ipc_group;
};

// The largest control message read (a run config is at most kMaxYamlBytes); ZeroMQ drops the
// connection of a peer that sends more, before the daemon reads any of it.
inline constexpr std::int64_t kMaxControlMessageBytes = 2 * 1024 * 1024;

// Serves REQ and DEALER clients alike (the envelope is echoed back as it came). A message that is
// not a Request gets an Error MALFORMED reply; the server never stops for a bad client.
class ControlServer {
 public:
  ControlServer(zmq::context_t& context, const std::string& endpoint, RequestHandler handler,
                const ControlSecurity& security = {});

  // Sends the deferred replies that are ready, then waits up to `timeout_ms` for one request and
  // answers it (or defers it). Returns true if a request was served.
  bool serve_one(int timeout_ms);
  const std::string& endpoint() const { return endpoint_; }
  std::size_t deferred() const { return pending_.size(); }

 private:
  struct Pending {
    std::vector<zmq::message_t> envelope;
    std::uint64_t id = 0;
    DeferredReply reply;
  };
  void send(std::vector<zmq::message_t>& envelope, const msg::Reply& reply);
  void send_ready_deferred();

  zmq::socket_t socket_;
  std::string endpoint_;
  RequestHandler handler_;
  std::vector<Pending> pending_;
};

// An Error reply with a code and message.
msg::Reply error_reply(std::uint64_t id, msg::Error::Code code, const std::string& message);

// One control message as the server answers it: the bytes parsed as a Request (MALFORMED when they
// are not one or name no operation) and handed to `handler`, whose exceptions become error replies.
// A deferred reply comes back in `deferred`, `reply` then holding only the request's id.
struct Answer {
  msg::Reply reply;
  std::optional<DeferredReply> deferred;
};
Answer answer_message(const void* data, std::size_t size, const RequestHandler& handler);
// A deferred reply once it is ready, with the request's id; its exception mapped as above.
msg::Reply finish_deferred(std::uint64_t id, DeferredReply& reply);

}  // namespace plenopiv::daemon
