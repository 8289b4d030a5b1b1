// Camera profiles: how one camera model does double exposure, in its own GenICam feature names.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace plenopiv::drivers {

// One `Feature: value` assignment, applied in the order the profile lists it.
struct FeatureSetting {
  std::string feature;
  std::string value;
};

// There is no standard GenICam feature for PIV double exposure: each model has its own (SFNC
// TriggerSelector=FrameBurstStart with AcquisitionBurstFrameCount=2, JAI TriggerOption=PIV, ...).
// A profile (YAML, drivers/camera/aravis/profiles/) maps our settings onto those names.
struct CameraProfile {
  std::string name;
  std::string source;  // file it came from, for messages
  // "burst": one trigger makes frames A and B in the camera. "two-frames": the fallback, the
  // camera takes one frame per trigger edge and the pair is made of two consecutive frames.
  std::string mode = "burst";
  std::vector<FeatureSetting> features;          // applied on arm
  std::vector<FeatureSetting> external_trigger;  // applied on arm for TriggerSource::External
  std::vector<FeatureSetting> software_trigger;  // applied on arm for TriggerSource::Software
  std::string software_trigger_command = "TriggerSoftware";
  int software_trigger_repeat = 1;  // commands per pair (2 in two-frames mode)
  // Pause between those commands; the second also waits (at most 0.5 s) for frame A to arrive.
  double software_trigger_spacing_s = 0;
  // Software triggers of consecutive pairs are at least this far apart, so that the gap between
  // pairs stays well above max_pair_gap_s (the rate a real trigger line would have).
  double min_pair_period_s = 0;
  double max_pair_gap_s = 0.05;
  int frame_id_bits = 16;  // GigE Vision 1.x block ids; 64 for extended ids / USB3 Vision

  // Every feature the profile names, with the value it needs (for enumerations).
  std::vector<FeatureSetting> all_settings() const;
};

// Reads a profile; InputError naming the file and key on any mistake.
CameraProfile load_camera_profile(const std::filesystem::path& file);
// The profile `name` (e.g. "sfnc-burst") from camera_profile_dir(). Names only: a path (or any
// character beyond letters, digits, '.', '_', '-') is an InputError, since URIs may come from requests.
CameraProfile find_camera_profile(const std::string& name);
// Where the shipped profiles are (PLENOPIV_CAMERA_PROFILE_DIR overrides).
std::filesystem::path camera_profile_dir();

// What a device says about a feature: nullopt if it has no such feature; otherwise the values it
// accepts if it is an enumeration (empty for other kinds).
using FeatureProbe = std::function<std::optional<std::vector<std::string>>(const std::string& feature)>;

// Checks every feature and enumeration value the profile needs against the device. Throws
// InputError naming the camera, the profile and every missing feature or value.
void check_camera_profile(const CameraProfile& profile, const FeatureProbe& probe, const std::string& camera);

}  // namespace plenopiv::drivers
