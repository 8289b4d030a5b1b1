// The control socket: a ZeroMQ ROUTER that answers every request with exactly one reply.
#include "daemon/control_server.hpp"

#include <spdlog/spdlog.h>

#include <vector>

#include "core/base/errors.hpp"
#include "daemon/run_state.hpp"

namespace plenopiv::daemon {

msg::Reply error_reply(std::uint64_t id, msg::Error::Code code, const std::string& message) {
  msg::Reply reply;
  reply.set_id(id);
  reply.mutable_error()->set_code(code);
  reply.mutable_error()->set_message(message);
  return reply;
}

ControlServer::ControlServer(zmq::context_t& context, const std::string& endpoint,
                             RequestHandler handler)
    : socket_(context, zmq::socket_type::router), endpoint_(endpoint), handler_(std::move(handler)) {
  socket_.set(zmq::sockopt::linger, 0);
  try {
    socket_.bind(endpoint);
  } catch (const zmq::error_t& e) {
    throw InputError("control endpoint " + endpoint + ": cannot bind: " + e.what());
  }
  endpoint_ = socket_.get(zmq::sockopt::last_endpoint);
}

bool ControlServer::serve_one(int timeout_ms) {
  zmq::pollitem_t item{socket_.handle(), 0, ZMQ_POLLIN, 0};
  try {
    zmq::poll(&item, 1, std::chrono::milliseconds(timeout_ms));
  } catch (const zmq::error_t& e) {
    if (e.num() == EINTR) return false;  // a signal: the caller checks why and goes on or stops
    throw;
  }
  if (!(item.revents & ZMQ_POLLIN)) return false;

  // Envelope: identity, then (REQ clients) an empty delimiter, then the body as last frame.
  std::vector<zmq::message_t> frames;
  do {
    zmq::message_t frame;
    if (!socket_.recv(frame, zmq::recv_flags::none)) return false;
    frames.push_back(std::move(frame));
  } while (socket_.get(zmq::sockopt::rcvmore));
  if (frames.size() < 2) return true;  // no body to answer: nothing a client waits for

  msg::Request request;
  msg::Reply reply;
  const zmq::message_t& body = frames.back();
  if (!request.ParseFromArray(body.data(), int(body.size()))) {
    reply = error_reply(0, msg::Error::MALFORMED,
                        "the control message (" + std::to_string(body.size()) +
                            " bytes) is not a plenopiv.msg.Request");
  } else if (request.kind_case() == msg::Request::KIND_NOT_SET) {
    reply = error_reply(request.id(), msg::Error::MALFORMED,
                        "the request names no operation (status, start_run, stop_run, "
                        "list_devices, calibrate)");
  } else {
    try {
      reply = handler_(request);
      reply.set_id(request.id());
    } catch (const InputError& e) {
      reply = error_reply(request.id(), msg::Error::INVALID, e.what());
    } catch (const WrongStateError& e) {
      reply = error_reply(request.id(), msg::Error::WRONG_STATE, e.what());
    } catch (const std::exception& e) {
      spdlog::error("control request {} failed: {}", request.id(), e.what());
      reply = error_reply(request.id(), msg::Error::INTERNAL, e.what());
    }
  }

  std::string bytes;
  reply.SerializeToString(&bytes);
  for (std::size_t i = 0; i + 1 < frames.size(); ++i) {
    socket_.send(frames[i], zmq::send_flags::sndmore);
  }
  socket_.send(zmq::buffer(bytes), zmq::send_flags::none);
  return true;
}

}  // namespace plenopiv::daemon
