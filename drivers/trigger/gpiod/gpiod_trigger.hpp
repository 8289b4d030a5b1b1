// `gpiod://<chip>?...`: trigger lines on a GPIO chip through libgpiod 1.6 (v1 API), user-space timed.
#pragma once

#include <memory>

#include "drivers/common/device_uri.hpp"
#include "drivers/trigger/trigger.hpp"

namespace plenopiv::drivers {

// User-space GPIO places an edge to within tens of microseconds (scheduler latency): the
// sequencer refuses schedules with smaller margins and points to hardware-timed mode.
constexpr double kGpiodTimingUncertainty_s = 50e-6;

// Opens the chip, checks every line offset, requests the outputs low and the Q-switch sync input
// for rising-edge events (kernel timestamps, CLOCK_MONOTONIC). InputError for an unknown chip or a
// line that does not exist; on any failure no line is left requested or high.
std::unique_ptr<Trigger> open_gpiod_trigger(const DeviceUri& uri);

}  // namespace plenopiv::drivers
