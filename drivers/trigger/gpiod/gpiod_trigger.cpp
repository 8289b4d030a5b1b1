// `gpiod://<chip>?...`: trigger lines on a GPIO chip through libgpiod 1.6 (v1 API), user-space timed.
#include "drivers/trigger/gpiod/gpiod_trigger.hpp"

#include <gpiod.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "core/base/errors.hpp"
#include "drivers/common/driver_errors.hpp"
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
      : ScheduledTrigger(TriggerInfo{uri.text(), "gpiod (user-space GPIO)", kGpiodTimingUncertainty_s, outputs_of(map),
                                     map.qsync.has_value()}),
        map_(map) {
    chip_ = map.chip.find('/') != std::string::npos ? gpiod_chip_open(map.chip.c_str())
                                                    : gpiod_chip_open_by_name(map.chip.c_str());
    if (!chip_) {
      uri.fail("cannot open GPIO chip '" + map.chip + "': " + std::strerror(errno) + " (chips: " + list_chips() +
               "; permissions: install systemd/60-plenopiv.rules)");
    }
    try {
      check_gpio_lines(map, gpiod_chip_num_lines(chip_), uri.text());
      for (const auto& [line, offset] : map.outputs) {
        gpiod_line* l = gpiod_chip_get_line(chip_, offset);
        if (!l || gpiod_line_request_output(l, kConsumer, 0) != 0) {
          throw DeviceError("trigger " + uri.text() + ": cannot request line " + std::to_string(offset) + " (" +
                            to_string(line) + ") as output: " + std::strerror(errno) +
                            " (is another program using it?)");
        }
        lines_[int(line)] = l;
      }
      if (map.qsync) {
        sync_line_ = gpiod_chip_get_line(chip_, *map.qsync);
        if (!sync_line_ || gpiod_line_request_rising_edge_events(sync_line_, kConsumer) != 0) {
          sync_line_ = nullptr;
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
    gpiod_line* l = lines_[int(line)];
    if (!l || gpiod_line_set_value(l, level ? 1 : 0) != 0) {
      throw DeviceError("trigger " + info().uri + ": cannot set " + to_string(line) + ": " + std::strerror(errno));
    }
  }

  void all_low() noexcept override {
    for (gpiod_line* l : lines_) {
      if (l) gpiod_line_set_value(l, 0);
    }
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
      const timespec timeout{0, 100'000'000};
      const int r = gpiod_line_event_wait(sync_line_, &timeout);
      if (r <= 0) continue;  // timeout, or an error that the next wait reports again
      gpiod_line_event event{};
      if (gpiod_line_event_read(sync_line_, &event) != 0) continue;
      if (event.event_type != GPIOD_LINE_EVENT_RISING_EDGE) continue;
      try {
        report_sync_edge(std::uint64_t(event.ts.tv_sec) * 1'000'000'000ull + std::uint64_t(event.ts.tv_nsec));
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
    for (gpiod_line*& l : lines_) {
      if (l) gpiod_line_release(l);
      l = nullptr;
    }
    if (sync_line_) gpiod_line_release(sync_line_);
    sync_line_ = nullptr;
    if (chip_) gpiod_chip_close(chip_);
    chip_ = nullptr;
  }

  GpioLineMap map_;
  gpiod_chip* chip_ = nullptr;
  gpiod_line* lines_[6] = {};
  gpiod_line* sync_line_ = nullptr;
  std::thread sync_thread_;
  std::atomic<bool> quit_sync_{false};
};

}  // namespace

std::unique_ptr<Trigger> open_gpiod_trigger(const DeviceUri& uri) {
  const GpioLineMap map = parse_gpio_line_map(uri);  // bad URIs fail before any device is touched
  return std::make_unique<GpiodTrigger>(uri, map);
}

}  // namespace plenopiv::drivers
