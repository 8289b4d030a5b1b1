// Progress of long offline work on stderr: a bar with rate and ETA on a terminal, plain lines otherwise.
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>

namespace plenopiv::client {

class Progress {
 public:
  // `label` names the work; `units` and `total` give the rate (e.g. "Mrays", 280.0).
  Progress(std::string label, std::string units, double total)
      : label_(std::move(label)),
        units_(std::move(units)),
        total_(total),
        tty_(::isatty(2) != 0),
        start_(std::chrono::steady_clock::now()) {}

  // fraction in [0, 1]; cheap to call often.
  void update(double fraction) {
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const double rate = elapsed > 0 ? fraction * total_ / elapsed : 0.0;
    const double eta = fraction > 0 ? elapsed * (1 - fraction) / fraction : 0.0;
    if (tty_) {
      const int width = 30, filled = int(fraction * width + 0.5);
      std::fprintf(stderr, "\r%s [%s%s] %3.0f%% %.1f %s/s ETA %.0f s ", label_.c_str(),
                   std::string(filled, '#').c_str(), std::string(width - filled, ' ').c_str(), 100 * fraction, rate,
                   units_.c_str(), eta);
      if (fraction >= 1) std::fputc('\n', stderr);
    } else if (fraction >= next_line_ || fraction >= 1) {
      // Not a terminal (a log, a pipe): a line per 10 %.
      std::fprintf(stderr, "%s: %.0f%% (%.1f %s/s, ETA %.0f s)\n", label_.c_str(), 100 * fraction, rate, units_.c_str(),
                   eta);
      while (next_line_ <= fraction) next_line_ += 0.1;
    }
  }

 private:
  std::string label_, units_;
  double total_;
  bool tty_;
  std::chrono::steady_clock::time_point start_;
  double next_line_ = 0.1;
};

}  // namespace plenopiv::client
