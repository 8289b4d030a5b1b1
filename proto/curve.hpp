// ZeroMQ CURVE for plenopivd and its clients: key pairs, certificate files, and securing a socket.
#pragma once

#include <filesystem>
#include <string>
#include <vector>
#include <zmq.hpp>

namespace plenopiv::wire {

// A CURVE key pair as ZeroMQ's Z85 text, 40 characters each. A public certificate has no secret.
struct CurveCertificate {
  std::string public_key;
  std::string secret_key;  // empty in a public certificate
};

// A fresh key pair (zmq_curve_keypair). Throws std::runtime_error when libzmq lacks CURVE.
CurveCertificate make_curve_certificate();

// Certificate files in the text format of pyzmq's zmq.auth and czmq's zcert (Python loads them with
// zmq.auth.load_certificate): `<dir>/<name>.key` holds the public key, `<dir>/<name>.key_secret`
// both keys and is readable by its owner only. Each file is written under a temporary name and
// renamed; an existing certificate is never overwritten (InputError naming it).
void write_certificate_files(const std::filesystem::path& dir, const std::string& name,
                             const CurveCertificate& certificate);
// Reads a certificate file (.key or .key_secret); InputError naming the file when it is missing,
// unreadable or holds no valid Z85 public key (or a malformed secret key).
CurveCertificate read_certificate(const std::filesystem::path& file);
// The public keys of every `*.key` file in `dir` (the clients a server admits); InputError naming
// the folder when it cannot be read, or a file when it is not a certificate.
std::vector<std::string> read_public_keys(const std::filesystem::path& dir);

// What a client socket needs to reach a CURVE server: the server's public key and the client's
// own key pair. Empty server key: the socket uses no security (ipc:// on this machine).
struct ClientSecurity {
  std::string server_public_key;
  CurveCertificate client;
  bool enabled() const { return !server_public_key.empty(); }
};
// From the server's certificate file and the client's secret certificate file; both empty: none.
// InputError when only one is given or a file is not a certificate.
ClientSecurity client_security(const std::filesystem::path& server_certificate,
                               const std::filesystem::path& client_certificate);
// Sets a client socket's CURVE options (before connect); nothing when security is not enabled.
void secure_client(zmq::socket_t& socket, const ClientSecurity& security);
// Makes `socket` a CURVE server with `server`'s key pair whose clients are checked by the ZAP
// handler under `zap_domain` (before bind).
void secure_server(zmq::socket_t& socket, const CurveCertificate& server, const std::string& zap_domain);

}  // namespace plenopiv::wire
