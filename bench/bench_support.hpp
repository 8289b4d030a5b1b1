// What several benchmarks print alike: a hash of float bits (bit-identity across builds) and the
// process's peak memory.
#pragma once

#include <sys/resource.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>

namespace plenopiv::bench {

inline constexpr std::uint64_t kFnvOffset = 1469598103934665603ull;

// FNV-1a over the bits of `values`, continuing from `hash` (chain several arrays by passing the
// previous result): equal hashes mean bit-identical results. Speed work must leave them unchanged,
// or say why not.
inline std::uint64_t bits_hash(std::span<const float> values, std::uint64_t hash = kFnvOffset) {
  for (float x : values) {
    std::uint32_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    hash = (hash ^ bits) * 1099511628211ull;
  }
  return hash;
}

// Process CPU seconds so far (user + system, every thread): on a shared machine wall time
// includes waiting for a core, CPU time much less so.
inline double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// Peak resident memory of this process so far (VmHWM), GB; -1 where /proc does not say.
inline double peak_rss_gb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / (1024.0 * 1024.0);
  return -1;
}

// Resident memory now (VmRSS), GB; -1 when /proc/self/status does not say.
inline double rss_gb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / (1024.0 * 1024.0);
  return -1;
}

// Threads of this process now (/proc/self/status Threads); -1 when it does not say.
inline int thread_count() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("Threads:", 0) == 0) return std::stoi(line.substr(8));
  return -1;
}

// File descriptors this process holds open now (entries of /proc/self/fd, less the one that
// lists them).
inline int open_fd_count() {
  int n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator("/proc/self/fd")) ++n;
  return n - 1;
}

}  // namespace plenopiv::bench
