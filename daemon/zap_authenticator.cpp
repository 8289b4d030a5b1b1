// The ZAP handler (ZeroMQ RFC 27) of plenopivd: admits CURVE clients whose public key is allowed.
#include "daemon/zap_authenticator.hpp"

#include <spdlog/spdlog.h>

#include <vector>

namespace plenopiv::daemon {

ZapAuthenticator::ZapAuthenticator(zmq::context_t& context, std::set<std::string> allowed_keys)
    : socket_(context, zmq::socket_type::rep), allowed_(std::move(allowed_keys)) {
  socket_.set(zmq::sockopt::linger, 0);
  socket_.bind("inproc://zeromq.zap.01");
  thread_ = std::thread([this] { serve(); });
}

ZapAuthenticator::~ZapAuthenticator() {
  quit_ = true;
  if (thread_.joinable()) thread_.join();
}

void ZapAuthenticator::serve() {
  while (!quit_) {
    try {
      zmq::pollitem_t item{socket_.handle(), 0, ZMQ_POLLIN, 0};
      zmq::poll(&item, 1, std::chrono::milliseconds(100));
      if (!(item.revents & ZMQ_POLLIN)) continue;
      // version, request id, domain, address, routing id, mechanism, credentials...
      std::vector<zmq::message_t> frames;
      do {
        zmq::message_t frame;
        if (!socket_.recv(frame, zmq::recv_flags::none)) break;
        frames.push_back(std::move(frame));
      } while (socket_.get(zmq::sockopt::rcvmore));
      // A REP socket must answer whatever came: a short request gets a 500.
      const auto frame = [&](std::size_t i) { return i < frames.size() ? frames[i].to_string() : std::string(); };
      const std::string version = frame(0);
      const std::string request_id = frame(1);
      const std::string address = frame(3);
      const std::string mechanism = frame(5);
      std::string status = "400", text = "not allowed", user;
      if (version != "1.0" || frames.size() < 6) {
        status = "500";
        text = "unsupported ZAP version";
      } else if (mechanism == "NULL") {
        status = "200";
        text = "OK";
      } else if (mechanism == "CURVE" && frames.size() >= 7 && frames[6].size() == 32) {
        char z85[41];
        zmq_z85_encode(z85, frames[6].data<std::uint8_t>(), 32);
        user = z85;
        if (allowed_.count(user)) {
          status = "200";
          text = "OK";
        }
      }
      if (status == "200") {
        ++admitted_;
      } else {
        ++refused_;
        spdlog::warn("refused a {} connection from {}{}: {}", mechanism, address,
                     user.empty() ? "" : " with key " + user, text);
      }
      socket_.send(zmq::buffer(version), zmq::send_flags::sndmore);
      socket_.send(zmq::buffer(request_id), zmq::send_flags::sndmore);
      socket_.send(zmq::buffer(status), zmq::send_flags::sndmore);
      socket_.send(zmq::buffer(text), zmq::send_flags::sndmore);
      socket_.send(zmq::buffer(user), zmq::send_flags::sndmore);
      socket_.send(zmq::str_buffer(""), zmq::send_flags::none);
    } catch (const zmq::error_t& e) {
      if (e.num() == ETERM) return;
      spdlog::error("ZAP handler: {}", e.what());
    } catch (const std::exception& e) {
      // Never dies silently: a request it could not answer refuses that client (ZeroMQ's
      // handshake times out), and the handler serves the next.
      spdlog::error("ZAP handler: {}", e.what());
    }
  }
}

}  // namespace plenopiv::daemon
