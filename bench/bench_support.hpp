// What several benchmarks print alike: a hash of float bits (bit-identity across builds), medians,
// wall and CPU time, and the process's memory, threads and file descriptors.
#pragma once

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <vector>

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

// The median of `v` (of an even count, the upper of the middle two); 0 when empty.
inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

// Seconds on the steady clock: the difference of two calls is the wall time between them.
inline double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Process CPU seconds so far (user + system, every thread): on a shared machine wall time
// includes waiting for a core, CPU time much less so.
inline double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// The number after `key` (e.g. "VmRSS:") in /proc/self/status, in the file's unit (kB for memory);
// -1 when it does not say.
inline double proc_status_value(const std::string& key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(key, 0) == 0) return std::stod(line.substr(key.size()));
  return -1;
}

// Peak resident memory of this process so far (VmHWM), GB; -1 where /proc does not say.
inline double peak_rss_gb() {
  const double kb = proc_status_value("VmHWM:");
  return kb < 0 ? -1 : kb / (1024.0 * 1024.0);
}

// Resident memory now (VmRSS), GB; -1 when /proc/self/status does not say.
inline double rss_gb() {
  const double kb = proc_status_value("VmRSS:");
  return kb < 0 ? -1 : kb / (1024.0 * 1024.0);
}

// Threads of this process now (/proc/self/status Threads); -1 when it does not say.
inline int thread_count() { return int(proc_status_value("Threads:")); }

// File descriptors this process holds open now (entries of /proc/self/fd, less the one that
// lists them).
inline int open_fd_count() {
  int n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator("/proc/self/fd")) ++n;
  return n - 1;
}

}  // namespace plenopiv::bench
