// Real child processes for integration tests: spawn, capture output, signal, wait with a timeout.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace plenopiv::testing_support {

class ChildProcess {
 public:
  // Starts `argv[0]` with its arguments; stdout and stderr go to `log_file`.
  ChildProcess(const std::vector<std::string>& argv, const std::filesystem::path& log_file);
  ~ChildProcess();  // kills the child if still running
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  void signal(int sig);
  // Exit status (or 128 + signal) once the child ended, nullopt on timeout.
  std::optional<int> wait(std::chrono::milliseconds timeout);
  bool running();
  pid_t pid() const { return pid_; }
  std::string output() const;  // what the child wrote so far

 private:
  pid_t pid_ = -1;
  std::optional<int> status_;
  std::filesystem::path log_file_;
};

// Runs a command to completion; returns its exit status and fills `output`.
int run_command(const std::vector<std::string>& argv, std::string& output,
                std::chrono::milliseconds timeout = std::chrono::seconds(60));

// A TCP port on 127.0.0.1 that was free a moment ago.
int free_tcp_port();

// Where the build put a program: build/bin/<name>.
std::string binary(const std::string& name);

}  // namespace plenopiv::testing_support
