// `plenopiv keys`: makes CURVE certificate files for plenopivd and its clients.
#include <iostream>
#include <memory>

#include "clients/cli/commands.hpp"
#include "core/base/errors.hpp"
#include "proto/curve.hpp"

namespace plenopiv::client {

void add_keys_commands(CLI::App& app) {
  auto dir = std::make_shared<std::string>(".");
  auto name = std::make_shared<std::string>();
  auto* keys =
      app.add_subcommand("keys",
                         "make a CURVE key pair: <name>.key (public: give it to the other side) and <name>.key_secret "
                         "(keep it: mode 0600)");
  keys->add_option("name", *name, "certificate name, e.g. plenopivd or operator-desk")->required();
  keys->add_option("-o,--output", *dir, "folder to write the two files to")->capture_default_str();
  keys->callback([dir, name] {
    if (!std::filesystem::is_directory(*dir)) throw InputError(*dir + ": no such folder");
    const wire::CurveCertificate certificate = wire::make_curve_certificate();
    wire::write_certificate_files(*dir, *name, certificate);
    const std::filesystem::path base = std::filesystem::path(*dir) / *name;
    std::cout << "wrote " << base.string() << ".key (public) and " << base.string()
              << ".key_secret (secret, owner only)\n"
              << "public key " << certificate.public_key << "\n"
              << "For the daemon: curve: {server_certificate: <daemon>.key_secret, authorized_clients: <folder "
                 "of client .key files>}.\n"
              << "For a client: plenopiv --endpoint tcp://<host>:5555 --server-key <daemon>.key --client-cert "
                 "<client>.key_secret status\n";
  });
}

}  // namespace plenopiv::client
