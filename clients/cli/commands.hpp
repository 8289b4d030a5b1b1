// The subcommands of `plenopiv`, each group added to the app by its own file.
#pragma once

#include <CLI/CLI.hpp>

#include "proto/curve.hpp"

namespace plenopiv::client {

// Options every control command shares.
struct ControlOptions {
  std::string endpoint = "ipc:///run/plenopiv/control";
  double timeout_s = 3.0;
  std::string server_key;   // the daemon's public certificate (CURVE over tcp://)
  std::string client_cert;  // this client's secret certificate (CURVE over tcp://)
  wire::ClientSecurity security() const { return wire::client_security(server_key, client_cert); }
};

void add_control_commands(CLI::App& app, ControlOptions& options);
void add_camera_commands(CLI::App& app);
void add_simulate_commands(CLI::App& app);
void add_piv_commands(CLI::App& app);
void add_recon_commands(CLI::App& app);
void add_process_commands(CLI::App& app);
void add_calib_commands(CLI::App& app);
void add_lightfield_commands(CLI::App& app);
void add_run_commands(CLI::App& app, ControlOptions& options);
void add_keys_commands(CLI::App& app);
void add_slurm_commands(CLI::App& app);
void add_export_commands(CLI::App& app);

}  // namespace plenopiv::client
