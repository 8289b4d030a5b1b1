// plenopivd's command line: reads the config, runs the Daemon until SIGTERM/SIGINT, stops cleanly.
#include "daemon/daemon_main.hpp"

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>
#include <CLI/CLI.hpp>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <iostream>

#include "core/base/errors.hpp"
#include "core/base/isa.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/logging/logging.hpp"

namespace plenopiv::daemon {
namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

}  // namespace

int daemon_main(int argc, char** argv, const DaemonExtensions& extensions) {
  CLI::App app{"plenopivd: single-camera plenoptic 3D/3C PIV daemon"};
  app.set_version_flag("--version", std::string(PLENOPIV_VERSION));
  std::filesystem::path config_path;
  std::string control, publish, data_dir, log_level, camera_uri, camera_file, calibration_file, replay_dir;
  bool simulation = false;
  app.add_option("-c,--config", config_path, "daemon config (plenopivd.yaml)")->check(CLI::ExistingFile);
  app.add_option("--control", control,
                 "control endpoint (overrides the config): ipc://<socket file>, or tcp:// with curve: configured");
  app.add_option("--publish", publish, "publishing endpoint (overrides the config)");
  app.add_option("--data-dir", data_dir, "where run folders are written (overrides the config)");
  app.add_option("--camera", camera_uri, "default camera URI (overrides the config)");
  app.add_option("--camera-file", camera_file,
                 "camera description (YAML) the processing and sim:// use (overrides the config)")
      ->check(CLI::ExistingFile);
  app.add_option("--calibration-file", calibration_file,
                 "the rig's calibration file (HDF5, `plenopiv calibrate`) the processing uses (overrides the "
                 "config)");
  app.add_flag("--simulation", simulation, "enable the simulated camera sim:// (as simulation: true)");
  app.add_option("--replay-dir", replay_dir,
                 "the only folder replay:// may read (needs --simulation; overrides the config)")
      ->check(CLI::ExistingDirectory);
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error");
  CLI11_PARSE(app, argc, argv);

  try {
    DaemonConfig config;
    if (!config_path.empty()) config = load_daemon_config(config_path);
    if (!control.empty()) config.control_endpoint = control;
    if (!publish.empty()) config.publish_endpoint = publish;
    if (!data_dir.empty()) config.data_dir = data_dir;
    if (!camera_uri.empty()) config.camera_uri = camera_uri;
    if (!camera_file.empty()) config.camera_file = camera_file;
    if (!calibration_file.empty()) config.calibration_file = calibration_file;
    if (simulation) config.simulation = true;
    if (!replay_dir.empty()) config.replay_dir = replay_dir;
    if (!log_level.empty()) config.log_level = log_level;
    validate(config, config_path.empty() ? "command line" : config_path.string());
    setup_logging("plenopivd", config.log_level);
    spdlog::info("kernels: the {} build (this CPU's best: {}; PLENOPIV_ISA picks a lower one)", isa_name(isa()),
                 isa_name(best_isa()));

    std::signal(SIGTERM, on_signal);
    std::signal(SIGINT, on_signal);
    Daemon daemon(std::move(config), extensions);
    daemon.serve(g_stop);
    sd_notify(0, "STOPPING=1\nSTATUS=Stopping: closing the run");
    spdlog::info("plenopivd stopping");
    daemon.shutdown();
    return 0;
  } catch (const InputError& e) {
    std::cerr << "plenopivd: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "plenopivd: fatal: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace plenopiv::daemon
