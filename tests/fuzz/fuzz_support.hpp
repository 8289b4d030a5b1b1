// Fuzz targets: what every harness needs — the input as text or as a file, and the rule that bad
// input is an InputError naming its source (anything else escapes and fails the target).
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "core/base/errors.hpp"

namespace plenopiv::fuzzing {

inline std::string as_text(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

// A folder of this process's own for files a harness writes: on /dev/shm when there is one (a
// file per input must not cost a disk write), else the temporary folder. Removed when the process
// exits (a crash leaves it; libFuzzer keeps the crashing input elsewhere).
inline const std::filesystem::path& scratch_dir() {
  // Never destroyed: the exit handler reads it after static destructors have run.
  static const std::filesystem::path* dir = [] {
    const std::filesystem::path base =
        std::filesystem::is_directory("/dev/shm") ? "/dev/shm" : std::filesystem::temp_directory_path();
    auto* d = new std::filesystem::path(base / ("plenopiv-fuzz-" + std::to_string(::getpid())));
    std::filesystem::remove_all(*d);  // left by an earlier process with the same pid
    std::filesystem::create_directories(*d);
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(scratch_dir(), ignored);
    });
    return d;
  }();
  return *dir;
}

// Writes the input to `name` in the scratch folder and returns its path.
inline std::filesystem::path input_file(const std::uint8_t* data, std::size_t size, const std::string& name) {
  const auto path = scratch_dir() / name;
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return path;
}

// A property of the code under test that does not hold: report it and abort, so libFuzzer keeps
// the input (and a regression replay fails).
[[noreturn]] inline void broken(const std::string& what) {
  std::fprintf(stderr, "fuzz property broken: %s\n", what.c_str());
  std::abort();
}

inline void require(bool ok, const std::string& what) {
  if (!ok) broken(what);
}

// A rejection must say what it rejects: the message names `culprit` (a source name, a file, a key).
inline void require_names(const InputError& e, std::string_view culprit) {
  const std::string_view m = e.what();
  require(m.find(culprit) != std::string_view::npos,
          "the InputError does not name '" + std::string(culprit) + "': " + std::string(m));
}

}  // namespace plenopiv::fuzzing
