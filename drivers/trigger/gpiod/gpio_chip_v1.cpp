// GpioChip over libgpiod 1.6's C API (the v1 API: a line object per line, requested one by one).
#include <gpiod.h>

#include <map>

#include "drivers/trigger/gpiod/gpio_chip.hpp"

namespace plenopiv::drivers {
namespace {

class GpioChipV1 final : public GpioChip {
 public:
  explicit GpioChipV1(gpiod_chip* chip) : chip_(chip) {}
  ~GpioChipV1() override {
    release();
    gpiod_chip_close(chip_);
  }

  int line_count() const override { return int(gpiod_chip_num_lines(chip_)); }

  bool request_output(unsigned offset, const char* consumer) override {
    gpiod_line* l = gpiod_chip_get_line(chip_, offset);
    if (!l || gpiod_line_request_output(l, consumer, 0) != 0) return false;
    outputs_[offset] = l;
    return true;
  }

  bool set(unsigned offset, bool high) noexcept override {
    const auto it = outputs_.find(offset);
    return it != outputs_.end() && gpiod_line_set_value(it->second, high ? 1 : 0) == 0;
  }

  bool request_rising_edges(unsigned offset, const char* consumer) override {
    gpiod_line* l = gpiod_chip_get_line(chip_, offset);
    if (!l || gpiod_line_request_rising_edge_events(l, consumer) != 0) return false;
    edges_ = l;
    return true;
  }

  std::optional<std::uint64_t> wait_rising_edge(std::chrono::nanoseconds timeout) override {
    const timespec t{time_t(timeout.count() / 1'000'000'000), long(timeout.count() % 1'000'000'000)};
    if (!edges_ || gpiod_line_event_wait(edges_, &t) <= 0) return std::nullopt;
    gpiod_line_event event{};
    if (gpiod_line_event_read(edges_, &event) != 0 || event.event_type != GPIOD_LINE_EVENT_RISING_EDGE)
      return std::nullopt;
    return std::uint64_t(event.ts.tv_sec) * 1'000'000'000ull + std::uint64_t(event.ts.tv_nsec);
  }

  void release() noexcept override {
    for (auto& [offset, line] : outputs_) gpiod_line_release(line);
    outputs_.clear();
    if (edges_) gpiod_line_release(edges_);
    edges_ = nullptr;
  }

 private:
  gpiod_chip* chip_;
  std::map<unsigned, gpiod_line*> outputs_;
  gpiod_line* edges_ = nullptr;
};

}  // namespace

std::unique_ptr<GpioChip> GpioChip::open(const std::string& chip) {
  gpiod_chip* c =
      chip.find('/') != std::string::npos ? gpiod_chip_open(chip.c_str()) : gpiod_chip_open_by_name(chip.c_str());
  if (!c) return nullptr;
  return std::make_unique<GpioChipV1>(c);
}

std::string GpioChip::library_version() { return gpiod_version_string(); }

}  // namespace plenopiv::drivers
