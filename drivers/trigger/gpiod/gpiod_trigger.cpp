// `gpiod://<chip>?...`: trigger lines on a GPIO chip through libgpiod (GpioChip: v1 or v2), user-space timed.
#include "drivers/trigger/gpiod/gpiod_trigger.hpp"

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>

#include "core/base/errors.hpp"
#include "drivers/common/driver_errors.hpp"
#include "drivers/trigger/gpiod/gpio_chip.hpp"
#include "drivers/trigger/gpiod/line_map.hpp"
#include "drivers/trigger/scheduled_trigger.hpp"

namespace plenopiv::drivers {
namespace {

constexpr const char* kConsumer = "plenopiv";

std::string list_chips() {
  std::string out;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/dev", ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind("gpiochip", 0) == 0) out += (out.empty() ? "" : ", ") + name;
  }
  return out.empty() ? "none on this machine" : out;
}

class GpiodTrigger final : public ScheduledTrigger {
 public:
  GpiodTrigger(const DeviceUri& uri, const GpioLineMap& map)
      : ScheduledTrigger(TriggerInfo{uri.text(), "libgpiod " + GpioChip::library_version() + " (user-space GPIO)",
                                     kGpiodTimingUncertainty_s, outputs_of(map), map.qsync.has_value()}),
        map_(map),
        chip_(GpioChip::open(map.chip)) {
    if (!chip_) {
      uri.fail("cannot open GPIO chip '" + map.chip + "': " + std::strerror(errno) + " (chips: " + list_chips() +
               "; permissions: install systemd/60-plenopiv.rules)");
    }
    try {
      check_gpio_lines(map, chip_->line_count(), uri.text());
      for (const auto& [line, offset] : map.outputs) {
        if (!chip_->request_output(offset, kConsumer)) {
          throw DeviceError("trigger " + uri.text() + ": cannot request line " + std::to_string(offset) + " (" +
                            to_string(line) + ") as output: " + std::strerror(errno) +
                            " (is another program using it?)");
        }
      }
      if (map.qsync) {
        if (!chip_->request_rising_edges(*map.qsync, kConsumer)) {
          throw DeviceError("trigger " + uri.text() + ": cannot request line " + std::to_string(*map.qsync) +
                            " (qsync) for edge events: " + std::strerror(errno));
        }
        sync_thread_ = std::thread([this] { watch_sync(); });
      }
    } catch (...) {
      release();
      throw;
    }
  }

  ~GpiodTrigger() override {
    stop_playback();
    release();
  }

 protected:
  // The chip's device path and the line offset: the physical output, however the URI spells it.
  std::string line_identity(TriggerLine line) const override {
    const std::string chip = map_.chip.find('/') == std::string::npos ? "/dev/" + map_.chip : map_.chip;
    const auto it = map_.outputs.find(line);
    return "gpiod:" + chip + ":" + (it == map_.outputs.end() ? to_string(line) : std::to_string(it->second));
  }

  void write_line(TriggerLine line, bool level) override {
    const auto it = map_.outputs.find(line);
    if (it == map_.outputs.end() || !chip_->set(it->second, level)) {
      throw DeviceError("trigger " + info().uri + ": cannot set " + to_string(line) + ": " + std::strerror(errno));
    }
  }

  void all_low() noexcept override {
    if (!chip_) return;
    for (const auto& [line, offset] : map_.outputs) chip_->set(offset, false);
  }

 private:
  static std::vector<TriggerLine> outputs_of(const GpioLineMap& map) {
    std::vector<TriggerLine> out;
    for (const auto& [line, offset] : map.outputs) out.push_back(line);
    return out;
  }

  // Q-switch sync: kernel timestamps of rising edges, so each pair carries the real dt.
  void watch_sync() {
    while (!quit_sync_) {
      const auto edge_ns = chip_->wait_rising_edge(std::chrono::milliseconds(100));
      if (!edge_ns) continue;  // timeout, or an error that the next wait reports again
      try {
        report_sync_edge(*edge_ns);
      } catch (const std::exception&) {
        // Out of memory for one more measured shot: this edge goes unmeasured (its pair keeps the
        // nominal dt, "not measured"); the thread goes on.
      }
    }
  }

  void release() noexcept {
    quit_sync_ = true;
    if (sync_thread_.joinable()) sync_thread_.join();
    all_low();  // safe state before the lines are given back
    if (chip_) chip_->release();
  }

  GpioLineMap map_;
  std::unique_ptr<GpioChip> chip_;
  std::thread sync_thread_;
  std::atomic<bool> quit_sync_{false};
};

}  // namespace

std::unique_ptr<Trigger> open_gpiod_trigger(const DeviceUri& uri) {
  const GpioLineMap map = parse_gpio_line_map(uri);  // bad URIs fail before any device is touched
  return std::make_unique<GpiodTrigger>(uri, map);
}

}  // namespace plenopiv::drivers
