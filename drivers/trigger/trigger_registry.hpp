// Opens triggers by URI: one factory per scheme (`sim://`, `gpiod://`), like the camera registry.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/common/device_uri.hpp"
#include "drivers/trigger/trigger.hpp"

namespace plenopiv::drivers {

using TriggerFactory = std::function<std::unique_ptr<Trigger>(const DeviceUri& uri)>;

class TriggerRegistry {
 public:
  // The process-wide registry with the built-in backends (sim always, gpiod when built).
  static TriggerRegistry& instance();
  void add(const std::string& scheme, TriggerFactory factory);
  void add_unavailable(const std::string& scheme, const std::string& why);
  bool available(const std::string& scheme) const;
  std::vector<std::string> schemes() const;
  // InputError for a malformed URI, unknown or unavailable scheme, or a device that is not there.
  std::unique_ptr<Trigger> open(std::string_view uri) const;

 private:
  struct Entry {
    TriggerFactory factory;
    std::string why_unavailable;
  };
  mutable std::mutex mutex_;
  std::map<std::string, Entry> entries_;
};

std::unique_ptr<Trigger> open_trigger(std::string_view uri);

// Defined by the backend source CMake selects (gpiod built or not).
void register_builtin_trigger_backends(TriggerRegistry& registry);

}  // namespace plenopiv::drivers
