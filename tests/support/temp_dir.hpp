// A scratch folder per test process: ctest runs test cases in parallel processes.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

namespace plenopiv::testing_support {

// <tmp>/plenopiv-<area>-<pid>, created on first use.
inline std::filesystem::path temp_dir(const std::string& area) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("plenopiv-" + area + "-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace plenopiv::testing_support
