// The subcommands of `plenopiv`, each group added to the app by its own file.
#pragma once

#include <CLI/CLI.hpp>

namespace plenopiv::client {

// Options every control command shares.
struct ControlOptions {
  std::string endpoint = "tcp://127.0.0.1:5555";
  double timeout_s = 3.0;
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

}  // namespace plenopiv::client
