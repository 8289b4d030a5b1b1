// GpioChip over libgpiod 2.x's C API (the v2 API: settings and a request per set of lines; one
// request per line here, so that a refusal names its line).
#include <gpiod.h>

#include <map>

#include "drivers/trigger/gpiod/gpio_chip.hpp"

namespace plenopiv::drivers {
namespace {

// Owning handles for the v2 API's objects.
template <typename T, void (*Free)(T*)>
struct Deleter {
  void operator()(T* p) const noexcept {
    if (p) Free(p);
  }
};
using Settings = std::unique_ptr<gpiod_line_settings, Deleter<gpiod_line_settings, gpiod_line_settings_free>>;
using LineConfig = std::unique_ptr<gpiod_line_config, Deleter<gpiod_line_config, gpiod_line_config_free>>;
using RequestConfig = std::unique_ptr<gpiod_request_config, Deleter<gpiod_request_config, gpiod_request_config_free>>;
using ChipInfo = std::unique_ptr<gpiod_chip_info, Deleter<gpiod_chip_info, gpiod_chip_info_free>>;
using EventBuffer =
    std::unique_ptr<gpiod_edge_event_buffer, Deleter<gpiod_edge_event_buffer, gpiod_edge_event_buffer_free>>;

class GpioChipV2 final : public GpioChip {
 public:
  explicit GpioChipV2(gpiod_chip* chip) : chip_(chip), events_(gpiod_edge_event_buffer_new(16)) {}
  ~GpioChipV2() override {
    release();
    gpiod_chip_close(chip_);
  }

  int line_count() const override {
    const ChipInfo info(gpiod_chip_get_info(chip_));
    return info ? int(gpiod_chip_info_get_num_lines(info.get())) : 0;
  }

  bool request_output(unsigned offset, const char* consumer) override {
    Settings settings(gpiod_line_settings_new());
    if (!settings || gpiod_line_settings_set_direction(settings.get(), GPIOD_LINE_DIRECTION_OUTPUT) != 0 ||
        gpiod_line_settings_set_output_value(settings.get(), GPIOD_LINE_VALUE_INACTIVE) != 0)
      return false;
    gpiod_line_request* r = request(offset, settings.get(), consumer);
    if (!r) return false;
    outputs_[offset] = r;
    return true;
  }

  bool set(unsigned offset, bool high) noexcept override {
    const auto it = outputs_.find(offset);
    return it != outputs_.end() &&
           gpiod_line_request_set_value(it->second, offset,
                                        high ? GPIOD_LINE_VALUE_ACTIVE : GPIOD_LINE_VALUE_INACTIVE) == 0;
  }

  bool request_rising_edges(unsigned offset, const char* consumer) override {
    Settings settings(gpiod_line_settings_new());
    // Edge timestamps on CLOCK_MONOTONIC, as libgpiod 1.6's on a current kernel.
    if (!settings || !events_ || gpiod_line_settings_set_direction(settings.get(), GPIOD_LINE_DIRECTION_INPUT) != 0 ||
        gpiod_line_settings_set_edge_detection(settings.get(), GPIOD_LINE_EDGE_RISING) != 0 ||
        gpiod_line_settings_set_event_clock(settings.get(), GPIOD_LINE_CLOCK_MONOTONIC) != 0)
      return false;
    edges_ = request(offset, settings.get(), consumer);
    return edges_ != nullptr;
  }

  std::optional<std::uint64_t> wait_rising_edge(std::chrono::nanoseconds timeout) override {
    if (!edges_ || gpiod_line_request_wait_edge_events(edges_, timeout.count()) <= 0) return std::nullopt;
    const int n = gpiod_line_request_read_edge_events(edges_, events_.get(), 1);
    if (n <= 0) return std::nullopt;
    gpiod_edge_event* event = gpiod_edge_event_buffer_get_event(events_.get(), 0);
    if (!event || gpiod_edge_event_get_event_type(event) != GPIOD_EDGE_EVENT_RISING_EDGE) return std::nullopt;
    return gpiod_edge_event_get_timestamp_ns(event);
  }

  void release() noexcept override {
    for (auto& [offset, r] : outputs_) gpiod_line_request_release(r);
    outputs_.clear();
    if (edges_) gpiod_line_request_release(edges_);
    edges_ = nullptr;
  }

 private:
  gpiod_line_request* request(unsigned offset, gpiod_line_settings* settings, const char* consumer) {
    const LineConfig lines(gpiod_line_config_new());
    const RequestConfig config(gpiod_request_config_new());
    if (!lines || !config || gpiod_line_config_add_line_settings(lines.get(), &offset, 1, settings) != 0)
      return nullptr;
    gpiod_request_config_set_consumer(config.get(), consumer);
    return gpiod_chip_request_lines(chip_, config.get(), lines.get());
  }

  gpiod_chip* chip_;
  EventBuffer events_;
  std::map<unsigned, gpiod_line_request*> outputs_;
  gpiod_line_request* edges_ = nullptr;
};

}  // namespace

std::unique_ptr<GpioChip> GpioChip::open(const std::string& chip) {
  // v2 opens by path only: a bare name is a device under /dev, as v1's gpiod_chip_open_by_name.
  const std::string path = chip.find('/') != std::string::npos ? chip : "/dev/" + chip;
  gpiod_chip* c = gpiod_chip_open(path.c_str());
  if (!c) return nullptr;
  return std::make_unique<GpioChipV2>(c);
}

std::string GpioChip::library_version() { return gpiod_api_version(); }

}  // namespace plenopiv::drivers
