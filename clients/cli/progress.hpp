// Progress of long CLI work on stderr: a bar with rate and ETA on a terminal, plain lines otherwise.
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>

namespace plenopiv::client {

class Progress {
 public:
  Progress(std::string what, int total) : what_(std::move(what)), total_(total), tty_(isatty(STDERR_FILENO)) {}

  void step(int done) {
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const double rate = t > 0 ? done / t : 0;
    const double eta = rate > 0 ? (total_ - done) / rate : 0;
    if (tty_) {
      const int width = 30, filled = total_ > 0 ? width * done / total_ : width;
      std::fprintf(stderr, "\r%s [%s%s] %d/%d %.1f/s ETA %.0f s", what_.c_str(), std::string(filled, '#').c_str(),
                   std::string(width - filled, ' ').c_str(), done, total_, rate, eta);
      if (done == total_) std::fprintf(stderr, "\n");
    } else {
      std::fprintf(stderr, "%s: %d/%d (%.1f/s, ETA %.0f s)\n", what_.c_str(), done, total_, rate, eta);
    }
  }

 private:
  std::string what_;
  int total_;
  bool tty_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace plenopiv::client
