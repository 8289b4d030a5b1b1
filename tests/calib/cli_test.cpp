// `plenopiv calibrate`, `refocus` and `perspective` as a user runs them: files in, files out, and
// clear refusals (exit 2) for an image of the wrong size or without spots.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>

#include "core/calib/calibration_file.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "tests/calib/spot_render.hpp"
#include "tests/lightfield/particle_render.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

using testing_support::binary;
using testing_support::run_command;

ImageU16 to_u16(const ImageF& in) {
  ImageU16 out(in.width, in.height);
  for (std::size_t k = 0; k < in.size(); ++k) out.pixels[k] = std::uint16_t(std::clamp(in.pixels[k] + 0.5f, 0.0f, 65535.0f));
  return out;
}

class CalibCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::temp_dir("calib-cli");
  }
  void TearDown() override {
    if (!std::getenv("PLENOPIV_KEEP_TEST_FILES")) std::filesystem::remove_all(dir_);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::filesystem::path dir_;
  const std::string camera_ = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";
};

TEST_F(CalibCli, CalibrateRefocusPerspective) {
  const auto cam = optics::load_camera_file(camera_);
  testing_support::SpotScene scene;
  scene.rotation_deg = 0.5;
  scene.offset_x_mm = 0.01;
  scene.jitter_mm = 0.001;
  scene.noise_sigma = 5;
  const auto spots = testing_support::render_calibration(cam, scene);
  io::write_tiff(path("cal.tif"), to_u16(spots.image));
  io::write_tiff(path("white1.tif"), to_u16(testing_support::render_white(cam, spots, scene, 0.9)));
  io::write_tiff(path("white2.tif"), to_u16(testing_support::render_white(cam, spots, scene, 0.9)));

  std::string out;
  ASSERT_EQ(run_command({binary("plenopiv"), "calibrate", "--camera", camera_, "--calibration-image", path("cal.tif"),
                         "--white", path("white1.tif"), path("white2.tif"), "-o", path("cal.h5")},
                        out),
            0)
      << out;
  EXPECT_NE(out.find("2500 measured"), std::string::npos) << out;
  const calib::LoadedCalibration loaded = calib::load_calibration(path("cal.h5"), cam);
  EXPECT_EQ(loaded.lenses.centres_mm.size(), 2500u);

  // A particle 4 mm beyond the focal plane, seen through the true (jittered) lenses.
  const auto truth_lenses = optics::MicrolensArray::from_lattice(spots.lens_lattice);
  ImageF raw = testing_support::render_particles(cam, truth_lenses, {{0.2, -0.1, 4.0, 3e5}}, 200);
  io::write_tiff(path("raw.tif"), to_u16(raw));
  ASSERT_EQ(run_command({binary("plenopiv"), "refocus", "--camera", camera_, "--calibration", path("cal.h5"),
                         path("raw.tif"), "--z", "-2:6:2", "-o", path("stack.tif")},
                        out),
            0)
      << out;
  const auto stack = io::read_tiff_stack(path("stack.tif"));
  ASSERT_EQ(stack.size(), 5u);
  EXPECT_EQ(stack[0].width, 50);
  EXPECT_GT(std::filesystem::file_size(path("stack.png")), 100u);
  // The page at z = 4 mm is the sharpest (the peak holds most light).
  auto peak_share = [](const ImageF& im) {
    double sum = 0, top = 0;
    for (float v : im.pixels) {
      sum += v;
      top = std::max(top, double(v));
    }
    return top / sum;
  };
  for (int k : {0, 1, 2, 4}) EXPECT_GT(peak_share(stack[3]), peak_share(stack[k])) << k;

  ASSERT_EQ(run_command({binary("plenopiv"), "perspective", "--camera", camera_, "--calibration", path("cal.h5"),
                         path("raw.tif"), "--u", "-5", "5", "--v", "0", "0", "-o", path("views.tif"), "--sheet",
                         path("views.png")},
                        out),
            0)
      << out;
  EXPECT_EQ(io::read_tiff_stack(path("views.tif")).size(), 2u);
  EXPECT_TRUE(std::filesystem::exists(path("views.png")));
}

TEST_F(CalibCli, RefusesWrongSizeAndImagesWithoutSpots) {
  io::write_tiff(path("small.tif"), ImageU16(100, 80, 50));
  io::write_tiff(path("flat.tif"), ImageU16(850, 850, 50));
  std::string out;
  EXPECT_EQ(run_command({binary("plenopiv"), "calibrate", "--camera", camera_, "--calibration-image", path("small.tif"),
                         "--white", path("flat.tif"), "-o", path("cal.h5")},
                        out),
            2);
  EXPECT_NE(out.find("100 x 80 pixels, the camera file's sensor is 850 x 850"), std::string::npos) << out;
  EXPECT_EQ(run_command({binary("plenopiv"), "calibrate", "--camera", camera_, "--calibration-image", path("flat.tif"),
                         "--white", path("flat.tif"), "-o", path("cal.h5")},
                        out),
            2);
  EXPECT_NE(out.find("found 0 spots, expected about 2 500"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(path("cal.h5")));
}

}  // namespace
}  // namespace plenopiv
