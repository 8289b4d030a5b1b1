// Opens cameras by URI: one factory per scheme (`aravis://`, `sim://`, ...), chosen at run time.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/camera/camera.hpp"
#include "drivers/common/device_uri.hpp"

namespace plenopiv::drivers {

using CameraFactory = std::function<std::unique_ptr<Camera>(const DeviceUri& uri)>;

// Which backends exist is decided at build time (PLENOPIV_WITH_*) and by who registers: the
// aravis backend is built in when configured; the simulated camera registers itself under `sim`
// from its own library (see drivers/README.md). Asking for a scheme that is known but not
// available says why and how to get it; an unknown scheme lists the known ones.
class CameraRegistry {
 public:
  // The process-wide registry, holding the built-in backends.
  static CameraRegistry& instance();

  // Adds or replaces the factory for `scheme` (without "://").
  void add(const std::string& scheme, CameraFactory factory);
  // Marks `scheme` as known but not usable in this build; `why` is shown to whoever asks for it.
  void add_unavailable(const std::string& scheme, const std::string& why);
  bool available(const std::string& scheme) const;
  std::vector<std::string> schemes() const;  // every known scheme, available or not

  // Parses `uri` and opens the camera. InputError for a malformed URI, an unknown or unavailable
  // scheme, or a device that is not found (each message names the URI).
  std::unique_ptr<Camera> open(std::string_view uri) const;

 private:
  struct Entry {
    CameraFactory factory;  // empty when unavailable
    std::string why_unavailable;
  };
  mutable std::mutex mutex_;
  std::map<std::string, Entry> entries_;
};

// CameraRegistry::instance().open(uri).
std::unique_ptr<Camera> open_camera(std::string_view uri);

// Defined by the backend source CMake selects (aravis built or not).
void register_builtin_camera_backends(CameraRegistry& registry);

}  // namespace plenopiv::drivers
