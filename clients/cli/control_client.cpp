// A control connection to plenopivd: one request, one reply, a clear error after a timeout.
#include "clients/cli/control_client.hpp"

namespace plenopiv::client {

ControlClient::ControlClient(std::string endpoint, std::chrono::milliseconds timeout, wire::ClientSecurity security)
    : endpoint_(std::move(endpoint)), timeout_(timeout), security_(std::move(security)) {}

msg::Reply ControlClient::call(msg::Request request) {
  request.set_id(next_id_++);
  std::string bytes;
  request.SerializeToString(&bytes);

  // A fresh REQ socket per call: a REQ socket that timed out cannot send again.
  zmq::socket_t socket(context_, zmq::socket_type::req);
  socket.set(zmq::sockopt::linger, 0);
  socket.set(zmq::sockopt::rcvtimeo, int(timeout_.count()));
  socket.set(zmq::sockopt::sndtimeo, int(timeout_.count()));
  wire::secure_client(socket, security_);
  try {
    socket.connect(endpoint_);
  } catch (const zmq::error_t& e) {
    throw ControlError("cannot connect to plenopivd at " + endpoint_ + ": " + e.what());
  }
  const std::string waited = std::to_string(timeout_.count() / 1000.0).substr(0, 3) + " s";
  if (!socket.send(zmq::buffer(bytes), zmq::send_flags::none)) {
    throw ControlError("plenopivd at " + endpoint_ + " did not take the request within " + waited);
  }
  zmq::message_t answer;
  if (!socket.recv(answer, zmq::recv_flags::none)) {
    throw ControlError("no reply from plenopivd at " + endpoint_ + " within " + waited +
                       ": is it running? (systemctl status plenopivd)" +
                       (security_.enabled() ? "; does it admit this client's key? (its curve: authorized_clients)"
                        : endpoint_.rfind("tcp://", 0) == 0
                            ? "; a tcp:// control socket needs CURVE: --server-key and --client-cert"
                            : "; may this user open its socket? (the plenopiv group)"));
  }
  msg::Reply reply;
  if (!reply.ParseFromArray(answer.data(), int(answer.size()))) {
    throw ControlError("the answer from " + endpoint_ + " is not a plenopiv reply");
  }
  return reply;
}

}  // namespace plenopiv::client
