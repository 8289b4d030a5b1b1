// The GPIO chip calls the gpiod:// trigger makes, over libgpiod's C API: v1 (1.6, Debian 12) in
// gpio_chip_v1.cpp or v2 (2.x, Debian 13) in gpio_chip_v2.cpp, whichever CMake found.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace plenopiv::drivers {

// One open chip and the lines requested on it. Errors: a false or nullptr return with errno set,
// so that the trigger names the line and the cause in its message.
class GpioChip {
 public:
  // The chip `chip`: a path, or a name under /dev ("gpiochip0"); nullptr when it cannot be opened.
  static std::unique_ptr<GpioChip> open(const std::string& chip);
  // libgpiod's version, as the library reports it ("1.6.3", "2.2.1").
  static std::string library_version();
  virtual ~GpioChip() = default;

  virtual int line_count() const = 0;
  // Requests line `offset` as an output, driven low.
  virtual bool request_output(unsigned offset, const char* consumer) = 0;
  // Drives a requested output line.
  virtual bool set(unsigned offset, bool high) noexcept = 0;
  // Requests line `offset` as an input reporting rising edges (at most one such line).
  virtual bool request_rising_edges(unsigned offset, const char* consumer) = 0;
  // Waits up to `timeout` for a rising edge on that line: its kernel timestamp, ns (CLOCK_MONOTONIC);
  // nothing on a timeout or an error (the next wait reports it again).
  virtual std::optional<std::uint64_t> wait_rising_edge(std::chrono::nanoseconds timeout) = 0;
  // Gives every requested line back (outputs as they are: drive them low first).
  virtual void release() noexcept = 0;
};

}  // namespace plenopiv::drivers
