// A scratch folder per test process: ctest runs test cases in parallel processes.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <mutex>
#include <set>
#include <string>

namespace plenopiv::testing_support {

// <tmp>/plenopiv-<area>-<pid>, emptied on this process's first use: a folder of that name left by an
// earlier process with the same (recycled) pid must not hand this one its files.
inline std::filesystem::path temp_dir(const std::string& area) {
  const auto dir = std::filesystem::temp_directory_path() / ("plenopiv-" + area + "-" + std::to_string(::getpid()));
  static std::mutex mutex;
  static std::set<std::string> emptied;
  std::lock_guard lock(mutex);
  if (emptied.insert(area).second) std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// A control endpoint of its own for a daemon a test starts: an ipc:// socket file in this
// process's scratch folder (the daemon's local default kind; tcp:// needs CURVE).
inline std::string ipc_endpoint(const std::string& name) {
  static int counter = 0;
  return "ipc://" + (temp_dir("ipc") / (name + "-" + std::to_string(counter++))).string();
}

}  // namespace plenopiv::testing_support
