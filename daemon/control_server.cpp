// The control socket: a ZeroMQ ROUTER that answers every request with exactly one reply.
#include "daemon/control_server.hpp"

#include <grp.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <limits>
#include <vector>

#include "core/base/errors.hpp"
#include "daemon/run_state.hpp"
#include "proto/valid_text.hpp"

namespace plenopiv::daemon {

msg::Reply error_reply(std::uint64_t id, msg::Error::Code code, const std::string& message) {
  msg::Reply reply;
  reply.set_id(id);
  reply.mutable_error()->set_code(code);
  reply.mutable_error()->set_message(message);
  return reply;
}

namespace {

// Runs `make` (the reply) and maps the exceptions a handler may throw to error replies.
msg::Reply answer_or_error(std::uint64_t id, const std::function<msg::Reply()>& make) {
  try {
    msg::Reply reply = make();
    reply.set_id(id);
    return reply;
  } catch (const InputError& e) {
    return error_reply(id, msg::Error::INVALID, e.what());
  } catch (const WrongStateError& e) {
    return error_reply(id, msg::Error::WRONG_STATE, e.what());
  } catch (const std::exception& e) {
    spdlog::error("control request {} failed: {}", id, e.what());
    return error_reply(id, msg::Error::INTERNAL, e.what());
  }
}

// The reply of `make`, its text fields made valid UTF-8: an error may quote the request's bytes
// (a config key as the YAML parser read it) or a path, and a client refuses a reply whose string
// fields are not UTF-8.
msg::Reply answer(std::uint64_t id, const std::function<msg::Reply()>& make) {
  msg::Reply reply = answer_or_error(id, make);
  msg::make_text_valid_utf8(reply);
  return reply;
}

// Binds an ipc:// socket so that only its owner and group can connect: the folder is made, the
// file is created with no access for others (umask) and then given mode 0660 and `group_name`.
void bind_ipc(zmq::socket_t& socket, const std::string& endpoint, const std::string& group_name) {
  const std::filesystem::path file = endpoint.substr(6);
  std::error_code ec;
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path(), ec);
  if (ec) {
    throw InputError("control endpoint " + endpoint + ": cannot make its folder " + file.parent_path().string() + ": " +
                     ec.message());
  }
  gid_t gid = gid_t(-1);
  if (!group_name.empty()) {
    const struct group* g = getgrnam(group_name.c_str());
    if (!g) throw InputError("control_socket_group: no group '" + group_name + "' on this machine");
    gid = g->gr_gid;
  }
  const mode_t old_mask = ::umask(0117);
  try {
    socket.bind(endpoint);
  } catch (const zmq::error_t& e) {
    ::umask(old_mask);
    throw InputError("control endpoint " + endpoint + ": cannot bind: " + e.what());
  }
  ::umask(old_mask);
  if (::chmod(file.c_str(), 0660) != 0 || (gid != gid_t(-1) && ::chown(file.c_str(), uid_t(-1), gid) != 0)) {
    throw InputError("control endpoint " + endpoint +
                     ": cannot set the socket's owner and mode: " + std::strerror(errno));
  }
}

}  // namespace

Answer answer_message(const void* data, std::size_t size, const RequestHandler& handler) {
  msg::Request request;
  Answer out;
  if (size > std::size_t(std::numeric_limits<int>::max()) || !request.ParseFromArray(data, int(size))) {
    out.reply = error_reply(0, msg::Error::MALFORMED,
                            "the control message (" + std::to_string(size) + " bytes) is not a plenopiv.msg.Request");
  } else if (request.kind_case() == msg::Request::KIND_NOT_SET) {
    out.reply = error_reply(request.id(), msg::Error::MALFORMED,
                            "the request names no operation (status, start_run, stop_run, "
                            "list_devices, calibrate)");
  } else {
    out.reply = answer(request.id(), [&] {
      HandlerResult result = handler(request);
      if (auto* later = std::get_if<DeferredReply>(&result)) {
        out.deferred = std::move(*later);
        return msg::Reply();
      }
      return std::get<msg::Reply>(std::move(result));
    });
  }
  return out;
}

msg::Reply finish_deferred(std::uint64_t id, DeferredReply& reply) {
  return answer(id, [&] { return reply.get(); });
}

ControlServer::ControlServer(zmq::context_t& context, const std::string& endpoint, RequestHandler handler,
                             const ControlSecurity& security)
    : socket_(context, zmq::socket_type::router), endpoint_(endpoint), handler_(std::move(handler)) {
  socket_.set(zmq::sockopt::linger, 0);
  socket_.set(zmq::sockopt::maxmsgsize, kMaxControlMessageBytes);
  if (security.curve) wire::secure_server(socket_, *security.curve, "plenopiv-control");
  if (endpoint.rfind("ipc://", 0) == 0) {
    bind_ipc(socket_, endpoint, security.ipc_group);
  } else {
    try {
      socket_.bind(endpoint);
    } catch (const zmq::error_t& e) {
      throw InputError("control endpoint " + endpoint + ": cannot bind: " + e.what());
    }
  }
  endpoint_ = socket_.get(zmq::sockopt::last_endpoint);
}

void ControlServer::send(std::vector<zmq::message_t>& envelope, const msg::Reply& reply) {
  std::string bytes;
  reply.SerializeToString(&bytes);
  for (zmq::message_t& frame : envelope) socket_.send(frame, zmq::send_flags::sndmore);
  socket_.send(zmq::buffer(bytes), zmq::send_flags::none);
}

void ControlServer::send_ready_deferred() {
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (it->reply.wait_for(std::chrono::seconds(0)) != std::future_status::ready) {
      ++it;
      continue;
    }
    send(it->envelope, finish_deferred(it->id, it->reply));
    it = pending_.erase(it);
  }
}

bool ControlServer::serve_one(int timeout_ms) {
  send_ready_deferred();
  zmq::pollitem_t item{socket_.handle(), 0, ZMQ_POLLIN, 0};
  try {
    zmq::poll(&item, 1, std::chrono::milliseconds(pending_.empty() ? timeout_ms : std::min(timeout_ms, 10)));
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

  const zmq::message_t body = std::move(frames.back());
  frames.pop_back();
  Answer answered = answer_message(body.data(), body.size(), handler_);
  if (answered.deferred) {
    pending_.push_back({std::move(frames), answered.reply.id(), std::move(*answered.deferred)});
    return true;
  }
  send(frames, answered.reply);
  return true;
}

}  // namespace plenopiv::daemon
