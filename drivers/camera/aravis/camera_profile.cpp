// Camera profiles: how one camera model does double exposure, in its own GenICam feature names.
#include "drivers/camera/aravis/camera_profile.hpp"

#include <algorithm>
#include <cstdlib>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"

namespace plenopiv::drivers {
namespace {

std::vector<FeatureSetting> read_settings(const YamlMap& map, std::string_view key) {
  std::vector<FeatureSetting> out;
  if (!map.has(key)) return out;
  const YAML::Node list = map.node()[std::string(key)];
  if (!list.IsSequence()) map.fail(key, "must be a list of `Feature: value` entries");
  for (std::size_t i = 0; i < list.size(); ++i) {
    const YAML::Node item = list[i];
    if (!item.IsMap() || item.size() != 1) {
      map.fail(key, "entry " + std::to_string(i + 1) + " must be one `Feature: value`");
    }
    const auto it = item.begin();
    if (!it->second.IsScalar()) {
      map.fail(key,
               "entry " + std::to_string(i + 1) + " (" + it->first.as<std::string>() + "): value must be a scalar");
    }
    out.push_back({it->first.as<std::string>(), it->second.as<std::string>()});
  }
  return out;
}

}  // namespace

std::vector<FeatureSetting> CameraProfile::all_settings() const {
  std::vector<FeatureSetting> out = features;
  out.insert(out.end(), external_trigger.begin(), external_trigger.end());
  out.insert(out.end(), software_trigger.begin(), software_trigger.end());
  return out;
}

CameraProfile load_camera_profile(const std::filesystem::path& file) {
  const YamlMap map(load_yaml_file(file), file.string());
  map.reject_unknown({"name", "description", "mode", "features", "external_trigger", "software_trigger",
                      "software_trigger_command", "software_trigger_repeat", "software_trigger_spacing_s",
                      "min_pair_period_s", "max_pair_gap_s", "frame_id_bits"});
  CameraProfile p;
  p.source = file.string();
  p.name = map.string("name");
  p.mode = map.choice_or("mode", {"burst", "two-frames"}, "burst");
  p.features = read_settings(map, "features");
  p.external_trigger = read_settings(map, "external_trigger");
  p.software_trigger = read_settings(map, "software_trigger");
  p.software_trigger_command = map.string_or("software_trigger_command", "TriggerSoftware");
  p.software_trigger_repeat = map.integer_in("software_trigger_repeat", p.mode == "two-frames" ? 2 : 1, 1, 2);
  p.software_trigger_spacing_s = map.number_or("software_trigger_spacing_s", 0.0);
  if (p.software_trigger_spacing_s < 0 || p.software_trigger_spacing_s > 1) {
    map.fail("software_trigger_spacing_s", "must be within 0..1 s");
  }
  p.max_pair_gap_s = map.number_or("max_pair_gap_s", 0.05);
  // Bounded so that it converts to whole nanoseconds (a 1e300 s gap would not).
  if (p.max_pair_gap_s <= 0 || p.max_pair_gap_s > 10) map.fail("max_pair_gap_s", "must be within 0..10 s, above 0");
  p.min_pair_period_s = map.number_or("min_pair_period_s", 0.0);
  if (p.min_pair_period_s < 0 || p.min_pair_period_s > 10) {
    map.fail("min_pair_period_s", "must be within 0..10 s");
  }
  if (p.min_pair_period_s > 0 && p.min_pair_period_s < 2 * p.max_pair_gap_s) {
    map.fail("min_pair_period_s", "must be at least twice max_pair_gap_s, or pairs could mix");
  }
  p.frame_id_bits = map.integer_in("frame_id_bits", 16, 16, 64);
  if (p.frame_id_bits != 16 && p.frame_id_bits != 64) map.fail("frame_id_bits", "must be 16 or 64");
  if (p.mode == "two-frames" && p.software_trigger_repeat != 2 && !p.software_trigger.empty()) {
    map.fail("software_trigger_repeat", "two-frames mode needs 2 software triggers per pair");
  }
  return p;
}

std::filesystem::path camera_profile_dir() {
  if (const char* env = std::getenv("PLENOPIV_CAMERA_PROFILE_DIR"); env && *env) return env;
  return PLENOPIV_CAMERA_PROFILE_DIR;
}

CameraProfile find_camera_profile(const std::string& name) {
  // A name, never a path: a URI may come from a control request, and must not make the daemon open
  // a file of its choosing. Profiles are added to the profile folder instead.
  const bool plain =
      !name.empty() && name[0] != '.' && name.size() <= 64 &&
      name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-") == std::string::npos;
  if (!plain) {
    throw InputError("camera profile '" + name +
                     "': a profile name (letters, digits, '.', '_', '-'), not a path: "
                     "put the profile's YAML file into " +
                     camera_profile_dir().string() +
                     " (or the folder PLENOPIV_CAMERA_PROFILE_DIR names) and give its name");
  }
  const std::filesystem::path shipped = camera_profile_dir() / (name + ".yaml");
  if (!std::filesystem::exists(shipped)) {
    std::string known;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(camera_profile_dir(), ec)) {
      if (e.path().extension() == ".yaml") {
        known += (known.empty() ? "" : ", ") + e.path().stem().string();
      }
    }
    throw InputError("camera profile '" + name + "': not found in " + camera_profile_dir().string() +
                     " (shipped: " + known + ")");
  }
  return load_camera_profile(shipped);
}

void check_camera_profile(const CameraProfile& profile, const FeatureProbe& probe, const std::string& camera) {
  std::vector<std::string> problems;
  for (const FeatureSetting& s : profile.all_settings()) {
    const auto values = probe(s.feature);
    if (!values) {
      problems.push_back("feature " + s.feature + " is missing");
      continue;
    }
    if (!values->empty() && std::find(values->begin(), values->end(), s.value) == values->end()) {
      std::string list;
      for (const std::string& v : *values) list += (list.empty() ? "" : ", ") + v;
      problems.push_back("feature " + s.feature + " has no value " + s.value + " (it has: " + list + ")");
    }
  }
  if (profile.software_trigger.size() && !probe(profile.software_trigger_command)) {
    problems.push_back("command " + profile.software_trigger_command + " is missing");
  }
  if (problems.empty()) return;
  std::string text;
  for (const std::string& p : problems) text += (text.empty() ? "" : "; ") + p;
  throw InputError("camera " + camera + " does not support camera profile '" + profile.name + "' (" + profile.source +
                   "): " + text);
}

}  // namespace plenopiv::drivers
