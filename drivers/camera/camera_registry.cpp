// Opens cameras by URI: one factory per scheme (`aravis://`, `sim://`, ...), chosen at run time.
#include "drivers/camera/camera_registry.hpp"

#include "core/base/errors.hpp"

namespace plenopiv::drivers {

CameraRegistry& CameraRegistry::instance() {
  static CameraRegistry* registry = [] {
    auto* r = new CameraRegistry;
    // Until the simulated and replay camera libraries register themselves, say where they come
    // from.
    r->add_unavailable("sim",
                       "the simulated camera is not registered in this program (it registers "
                       "under sim:// from the simulated-camera driver library at start-up)");
    r->add_unavailable("replay",
                       "the replay camera is not registered in this program (it registers under "
                       "replay:// from the replay-camera driver library at start-up)");
    register_builtin_camera_backends(*r);
    return r;
  }();
  return *registry;
}

void CameraRegistry::add(const std::string& scheme, CameraFactory factory) {
  std::lock_guard lock(mutex_);
  entries_[scheme] = Entry{std::move(factory), {}};
}

void CameraRegistry::add_unavailable(const std::string& scheme, const std::string& why) {
  std::lock_guard lock(mutex_);
  entries_[scheme] = Entry{{}, why};
}

bool CameraRegistry::available(const std::string& scheme) const {
  std::lock_guard lock(mutex_);
  auto it = entries_.find(scheme);
  return it != entries_.end() && it->second.factory;
}

std::vector<std::string> CameraRegistry::schemes() const {
  std::lock_guard lock(mutex_);
  std::vector<std::string> out;
  for (const auto& [scheme, entry] : entries_) out.push_back(scheme);
  return out;
}

std::unique_ptr<Camera> CameraRegistry::open(std::string_view text) const {
  const DeviceUri uri = DeviceUri::parse(text);
  CameraFactory factory;
  {
    std::lock_guard lock(mutex_);
    auto it = entries_.find(uri.scheme());
    if (it == entries_.end()) {
      std::string known;
      for (const auto& [scheme, entry] : entries_) known += (known.empty() ? "" : ", ") + scheme;
      uri.fail("unknown camera scheme '" + uri.scheme() + "' (known: " + known + ")");
    }
    if (!it->second.factory) {
      uri.fail("camera backend '" + uri.scheme() + "' is not available: " + it->second.why_unavailable);
    }
    factory = it->second.factory;
  }
  return factory(uri);
}

std::unique_ptr<Camera> open_camera(std::string_view uri) { return CameraRegistry::instance().open(uri); }

}  // namespace plenopiv::drivers
