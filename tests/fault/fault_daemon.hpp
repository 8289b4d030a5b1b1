// The fault suite's plenopivd: a real daemon child process on a data folder.
#pragma once

#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/child_process.hpp"
#include "tests/support/daemon_status.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::fault {

namespace fs = std::filesystem;
using testing_support::binary;
using testing_support::ChildProcess;

// plenopivd with a data folder, `camera_file` and `camera` (simulation on: the sim:// trigger and
// camera), its control endpoint answering once it has started.
struct Daemon {
  std::string control = testing_support::ipc_endpoint("control");
  std::string publish = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  std::unique_ptr<ChildProcess> process;

  Daemon(const fs::path& data_dir, const fs::path& log, const std::string& camera_file, const std::string& camera) {
    process = std::make_unique<ChildProcess>(
        std::vector<std::string>{binary("plenopivd"), "--simulation", "--camera-file", camera_file, "--camera", camera,
                                 "--control", control, "--publish", publish, "--data-dir", data_dir.string()},
        log);
    for (int i = 0; i < 200 && !testing_support::probe_status(control); ++i) {
      if (!process->running()) break;
    }
  }
  bool answers() const { return testing_support::probe_status(control).has_value(); }

  // Asks for status until `done(status)` holds or `timeout` passes; the last status (nullopt: none).
  template <class Done>
  std::optional<msg::Status> wait_for(Done done, std::chrono::milliseconds timeout) const {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    std::optional<msg::Status> s;
    do {
      s = testing_support::probe_status(control);
      if (s && done(*s)) return s;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    } while (std::chrono::steady_clock::now() < deadline);
    return s;
  }

  int client(const std::vector<std::string>& args, std::string& out) const {
    std::vector<std::string> argv{binary("plenopiv"), "--endpoint", control};
    argv.insert(argv.end(), args.begin(), args.end());
    return testing_support::run_command(argv, out);
  }
};

}  // namespace plenopiv::fault
