// ZeroMQ CURVE for plenopivd and its clients: key pairs, certificate files, and securing a socket.
#include "proto/curve.hpp"

#include <sys/stat.h>

#include <cstdio>
#include <ctime>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"

namespace plenopiv::wire {
namespace fs = std::filesystem;
namespace {

// A Z85 key: 40 characters that decode to 32 bytes.
bool valid_z85_key(const std::string& key) {
  if (key.size() != 40) return false;
  std::uint8_t bytes[32];
  return zmq_z85_decode(bytes, key.c_str()) != nullptr;
}

// `    public-key = "<z85>"` and `    secret-key = "<z85>"` lines, as zcert and pyzmq write them.
std::string key_value(const std::string& text, const std::string& key) {
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    const auto at = line.find(key);
    if (at == std::string::npos || line.find_first_not_of(" \t") != at) continue;
    const auto eq = line.find('=', at + key.size());
    if (eq == std::string::npos) continue;
    std::string value = line.substr(eq + 1);
    const auto first = value.find_first_not_of(" \t\"");
    const auto last = value.find_last_not_of(" \t\"\r");
    if (first == std::string::npos || last == std::string::npos || last < first) return {};
    return value.substr(first, last - first + 1);
  }
  return {};
}

std::string certificate_text(const CurveCertificate& c, bool with_secret) {
  const std::time_t now = std::time(nullptr);
  char stamp[64];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%d %H:%M:%S UTC", std::gmtime(&now));
  std::string text = std::string("#   ****  Generated on ") + stamp + " by plenopiv keys  ****\n" +
                     (with_secret ? "#   ZeroMQ CURVE **Secret** Certificate\n"
                                    "#   DO NOT PROVIDE THIS FILE TO OTHER USERS nor change its permissions.\n"
                                  : "#   ZeroMQ CURVE Public Certificate\n"
                                    "#   Exchange securely, or use a secure mechanism to verify the contents\n"
                                    "#   of this file after exchange.\n") +
                     "\nmetadata\ncurve\n    public-key = \"" + c.public_key + "\"\n";
  if (with_secret) text += "    secret-key = \"" + c.secret_key + "\"\n";
  return text;
}

void write_new_file(const fs::path& path, const std::string& text, fs::perms mode) {
  if (fs::exists(path)) {
    throw InputError(path.string() + ": already exists; plenopiv keys never overwrites a certificate");
  }
  io::write_atomically(path, [&](const fs::path& tmp) {
    {
      std::ofstream out(tmp, std::ios::binary);
      out << text;
      out.close();
      if (!out) throw InputError(tmp.string() + ": cannot write");
    }
    fs::permissions(tmp, mode, fs::perm_options::replace);
  });
}

}  // namespace

CurveCertificate make_curve_certificate() {
  char public_key[41], secret_key[41];
  if (zmq_curve_keypair(public_key, secret_key) != 0) {
    throw std::runtime_error(std::string("cannot make a CURVE key pair: ") + zmq_strerror(zmq_errno()) +
                             " (libzmq built without CURVE?)");
  }
  return {public_key, secret_key};
}

void write_certificate_files(const fs::path& dir, const std::string& name, const CurveCertificate& c) {
  if (name.empty() || name.find('/') != std::string::npos || name[0] == '.') {
    throw InputError("certificate name '" + name + "': a plain file name, e.g. 'operator-desk'");
  }
  write_new_file(dir / (name + ".key"), certificate_text(c, false),
                 fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read | fs::perms::others_read);
  write_new_file(dir / (name + ".key_secret"), certificate_text(c, true),
                 fs::perms::owner_read | fs::perms::owner_write);
}

CurveCertificate read_certificate(const fs::path& file) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) {
    throw InputError(file.string() + ": no such certificate file (plenopiv keys makes them)");
  }
  if (fs::file_size(file, ec) > 64 * 1024) throw InputError(file.string() + ": too large for a certificate");
  std::ifstream in(file, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  if (!in) throw InputError(file.string() + ": cannot read the certificate");
  CurveCertificate c{key_value(text.str(), "public-key"), key_value(text.str(), "secret-key")};
  if (!valid_z85_key(c.public_key)) {
    throw InputError(file.string() + ": no valid public-key (40 Z85 characters) in the certificate");
  }
  if (!c.secret_key.empty() && !valid_z85_key(c.secret_key)) {
    throw InputError(file.string() + ": the secret-key is not 40 Z85 characters");
  }
  return c;
}

std::vector<std::string> read_public_keys(const fs::path& dir) {
  std::error_code ec;
  fs::directory_iterator it(dir, ec);
  if (ec) throw InputError(dir.string() + ": cannot read the folder of client certificates: " + ec.message());
  std::vector<std::string> keys;
  for (const auto& entry : it) {
    if (entry.path().extension() != ".key") continue;
    keys.push_back(read_certificate(entry.path()).public_key);
  }
  return keys;
}

ClientSecurity client_security(const fs::path& server_certificate, const fs::path& client_certificate) {
  if (server_certificate.empty() && client_certificate.empty()) return {};
  if (server_certificate.empty() || client_certificate.empty()) {
    throw InputError(
        "CURVE needs both the server's certificate (--server-key) and this client's secret "
        "certificate (--client-cert)");
  }
  ClientSecurity s;
  s.server_public_key = read_certificate(server_certificate).public_key;
  s.client = read_certificate(client_certificate);
  if (s.client.secret_key.empty()) {
    throw InputError(client_certificate.string() +
                     ": holds no secret-key: give the client's .key_secret file, not its public .key");
  }
  return s;
}

void secure_client(zmq::socket_t& socket, const ClientSecurity& security) {
  if (!security.enabled()) return;
  socket.set(zmq::sockopt::curve_serverkey, security.server_public_key);
  socket.set(zmq::sockopt::curve_publickey, security.client.public_key);
  socket.set(zmq::sockopt::curve_secretkey, security.client.secret_key);
}

void secure_server(zmq::socket_t& socket, const CurveCertificate& server, const std::string& zap_domain) {
  if (server.secret_key.empty()) throw std::logic_error("secure_server: the server certificate has no secret key");
  socket.set(zmq::sockopt::curve_server, 1);
  socket.set(zmq::sockopt::curve_secretkey, server.secret_key);
  socket.set(zmq::sockopt::zap_domain, zap_domain);
}

}  // namespace plenopiv::wire
