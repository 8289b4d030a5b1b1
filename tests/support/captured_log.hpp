// Tests: what the code under test logged through spdlog's default logger, read back as lines.
#pragma once

#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

namespace plenopiv::testing_support {

// For its lifetime, spdlog's default logger is one that keeps the last `capacity` formatted lines
// (level info and above); the logger it replaced comes back when it is destroyed, also when a test
// fails or throws half way.
class CapturedLog {
 public:
  explicit CapturedLog(std::size_t capacity = 64)
      : sink_(std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(capacity)), previous_(spdlog::default_logger()) {
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("captured", sink_));
  }
  ~CapturedLog() { spdlog::set_default_logger(previous_); }
  CapturedLog(const CapturedLog&) = delete;
  CapturedLog& operator=(const CapturedLog&) = delete;

  std::vector<std::string> lines() const { return sink_->last_formatted(); }

 private:
  std::shared_ptr<spdlog::sinks::ringbuffer_sink_mt> sink_;
  std::shared_ptr<spdlog::logger> previous_;
};

}  // namespace plenopiv::testing_support
