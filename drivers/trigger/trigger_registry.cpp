// Opens triggers by URI: one factory per scheme (`sim://`, `gpiod://`), like the camera registry.
#include "drivers/trigger/trigger_registry.hpp"

#include "drivers/trigger/sim_trigger.hpp"

namespace plenopiv::drivers {

TriggerRegistry& TriggerRegistry::instance() {
  static TriggerRegistry* registry = [] {
    auto* r = new TriggerRegistry;
    r->add("sim", [](const DeviceUri& uri) { return open_sim_trigger(uri); });
    register_builtin_trigger_backends(*r);
    return r;
  }();
  return *registry;
}

void TriggerRegistry::add(const std::string& scheme, TriggerFactory factory) {
  std::lock_guard lock(mutex_);
  entries_[scheme] = Entry{std::move(factory), {}};
}

void TriggerRegistry::add_unavailable(const std::string& scheme, const std::string& why) {
  std::lock_guard lock(mutex_);
  entries_[scheme] = Entry{{}, why};
}

bool TriggerRegistry::available(const std::string& scheme) const {
  std::lock_guard lock(mutex_);
  auto it = entries_.find(scheme);
  return it != entries_.end() && it->second.factory;
}

std::vector<std::string> TriggerRegistry::schemes() const {
  std::lock_guard lock(mutex_);
  std::vector<std::string> out;
  for (const auto& [scheme, entry] : entries_) out.push_back(scheme);
  return out;
}

std::unique_ptr<Trigger> TriggerRegistry::open(std::string_view text) const {
  const DeviceUri uri = DeviceUri::parse(text);
  TriggerFactory factory;
  {
    std::lock_guard lock(mutex_);
    auto it = entries_.find(uri.scheme());
    if (it == entries_.end()) {
      std::string known;
      for (const auto& [scheme, entry] : entries_) known += (known.empty() ? "" : ", ") + scheme;
      uri.fail("unknown trigger scheme '" + uri.scheme() + "' (known: " + known + ")");
    }
    if (!it->second.factory) {
      uri.fail("trigger backend '" + uri.scheme() + "' is not available: " + it->second.why_unavailable);
    }
    factory = it->second.factory;
  }
  return factory(uri);
}

std::unique_ptr<Trigger> open_trigger(std::string_view uri) { return TriggerRegistry::instance().open(uri); }

}  // namespace plenopiv::drivers
