// Camera profiles: the shipped ones load, and a camera lacking a feature is named in the error.
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <map>

#include "core/base/errors.hpp"
#include "drivers/camera/aravis/camera_profile.hpp"

namespace plenopiv::drivers {
namespace {

// A device described by its features; enumerations list their values.
FeatureProbe device(std::map<std::string, std::vector<std::string>> features) {
  return [features](const std::string& name) -> std::optional<std::vector<std::string>> {
    auto it = features.find(name);
    if (it == features.end()) return std::nullopt;
    return it->second;
  };
}

TEST(CameraProfile, ShippedProfilesLoad) {
  for (const char* name : {"sfnc-burst", "jai-piv", "two-frames", "aravis-fake"}) {
    const CameraProfile p = find_camera_profile(name);
    EXPECT_EQ(p.name, name);
    EXPECT_FALSE(p.features.empty());
  }
  EXPECT_EQ(find_camera_profile("sfnc-burst").software_trigger_repeat, 1);
  EXPECT_EQ(find_camera_profile("aravis-fake").software_trigger_repeat, 2);
  EXPECT_EQ(find_camera_profile("aravis-fake").mode, "two-frames");
}

TEST(CameraProfile, UnknownProfileListsTheShippedOnes) {
  try {
    find_camera_profile("nosuch");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("sfnc-burst"), std::string::npos) << e.what();
  }
}

// A URI may come from a control request: its profile is a name in the profile folder, never a
// file the daemon would open (and quote in its error).
TEST(CameraProfile, APathIsNotAProfileName) {
  for (const std::string bad : {"/etc/passwd", "../../etc/passwd", "profiles/x", ".hidden", "a b", ""}) {
    try {
      find_camera_profile(bad);
      FAIL() << "'" << bad << "' was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("not a path"), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find("root:"), std::string::npos) << e.what();
    }
  }
}

TEST(CameraProfile, MissingFeaturesAndValuesAreNamed) {
  const CameraProfile p = find_camera_profile("sfnc-burst");
  auto fake_like = device({{"AcquisitionMode", {"Continuous"}},
                           {"TriggerSelector", {"FrameStart", "AcquisitionStart"}},
                           {"TriggerMode", {"Off", "On"}},
                           {"TriggerActivation", {"RisingEdge"}},
                           {"TriggerSource", {"Line0", "Software"}},
                           {"TriggerSoftware", {}}});
  try {
    check_camera_profile(p, fake_like, "aravis://x");
    FAIL();
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("feature TriggerSelector has no value FrameBurstStart (it has: FrameStart, "
                     "AcquisitionStart)"),
              std::string::npos)
        << m;
    EXPECT_NE(m.find("feature AcquisitionBurstFrameCount is missing"), std::string::npos) << m;
    EXPECT_NE(m.find("aravis://x"), std::string::npos) << m;
  }
  auto burst = device({{"AcquisitionMode", {"Continuous"}},
                       {"TriggerSelector", {"FrameBurstStart"}},
                       {"AcquisitionBurstFrameCount", {}},
                       {"TriggerMode", {"On"}},
                       {"TriggerActivation", {"RisingEdge"}},
                       {"TriggerSource", {"Line0", "Software"}},
                       {"TriggerSoftware", {}}});
  EXPECT_NO_THROW(check_camera_profile(p, burst, "aravis://y"));
}

TEST(CameraProfile, BadFilesNameTheKey) {
  const auto file =
      std::filesystem::temp_directory_path() / ("plenopiv-bad-profile-" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(file) << "name: bad\nmode: triple\nfeatures: []\n";
  try {
    load_camera_profile(file);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("mode"), std::string::npos) << e.what();
  }
  std::ofstream(file) << "name: bad\nfeatures:\n  - TriggerMode\n";
  EXPECT_THROW(load_camera_profile(file), InputError);
  // Whole numbers out of range are refused before they narrow to int (4294967297 would be 1, and
  // 4294967312 would be 16); a gap too long to convert to nanoseconds likewise.
  for (const std::string bad :
       {"software_trigger_repeat: 4294967297", "software_trigger_repeat: 3", "frame_id_bits: 4294967312",
        "frame_id_bits: 32", "max_pair_gap_s: 1e300", "max_pair_gap_s: 0"}) {
    std::ofstream(file) << "name: bad\nfeatures: []\n" << bad << "\n";
    try {
      load_camera_profile(file);
      ADD_FAILURE() << "accepted: " << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(bad.substr(0, bad.find(':'))), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace plenopiv::drivers
