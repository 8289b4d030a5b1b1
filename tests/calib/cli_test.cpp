// `plenopiv calibrate`, `refocus`, `perspective` and `reconstruct` as a user runs them: files in
// (TIFF, PNG, float TIFF; white frames alone with darks), files out, and clear refusals (exit 2)
// for an image of the wrong size, without spots, or in colour.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <numbers>
#include <opencv2/imgcodecs.hpp>

#include "core/calib/calibration_file.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "core/sim/render.hpp"
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
  for (std::size_t k = 0; k < in.size(); ++k)
    out.pixels[k] = std::uint16_t(std::clamp(in.pixels[k] + 0.5f, 0.0f, 65535.0f));
  return out;
}

// The share of a refocused page's light in its brightest pixel: highest where the particle is sharp.
double peak_share(const ImageF& im) {
  double sum = 0, top = 0;
  for (float v : im.pixels) {
    sum += v;
    top = std::max(top, double(v));
  }
  return top / sum;
}

class CalibCli : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing_support::temp_dir("calib-cli"); }
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
  // Each page stores the depth it brings into focus.
  const auto descriptions = io::read_tiff_descriptions(path("stack.tif"));
  ASSERT_EQ(descriptions.size(), 5u);
  for (int k = 0; k < 5; ++k) {
    const std::string& d = descriptions[std::size_t(k)];
    const auto at = d.find("z_mm=");
    ASSERT_NE(at, std::string::npos) << d;
    EXPECT_NEAR(std::stod(d.substr(at + 5)), -2.0 + 2 * k, 1e-6) << d;
    EXPECT_NE(d.find("alpha="), std::string::npos) << d;
  }
  EXPECT_EQ(stack[0].width, 50);
  EXPECT_GT(std::filesystem::file_size(path("stack.png")), 100u);
  // The page at z = 4 mm is the sharpest (the peak holds most light).
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

// 8-bit PNG counts of a rendered image, as a machine-vision camera's software saves them.
void write_png8(const std::string& path, const ImageU16& image) {
  cv::Mat m(image.height, image.width, CV_8U);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) m.at<std::uint8_t>(y, x) = std::uint8_t(std::min<int>(255, image.at(x, y)));
  ASSERT_TRUE(cv::imwrite(path, m));
}

// A real dataset's shape: two 8-bit PNG white frames and a dark frame, no stopped-down image;
// then a particle frame as float TIFF (refocus) and as PNG (reconstruct).
TEST_F(CalibCli, WhiteOnlyFromPngFramesThenRefocusAndReconstruct) {
  const auto cam = optics::load_camera_file(camera_);
  optics::Lattice l = optics::Lattice::nominal(cam);
  l.rotation_rad = 0.4 * std::numbers::pi / 180;
  l.offset_x_mm = 0.02;
  const optics::MicrolensArray truth = optics::MicrolensArray::from_lattice(l);
  sim::SensorModel sensor;
  sensor.bit_depth = 8;
  sensor.electrons_per_ray = 40;
  sensor.gain_dn_per_electron = 0.05;
  sensor.shot_noise = true;
  sensor.read_noise_electrons = 10;
  sensor.dark_offset_dn = 8;
  sim::TargetOptions white = sim::white_target();
  white.rays_per_lens = 30000;
  white.sensor = sensor;
  write_png8(path("white1.png"), sim::render_target(cam, truth, white, 1).image);
  write_png8(path("white2.png"), sim::render_target(cam, truth, white, 2).image);
  write_png8(path("dark.png"), sim::apply_sensor(ImageF(850, 850, 0.0f), sensor, 3));

  std::string out;
  ASSERT_EQ(run_command({binary("plenopiv"), "calibrate", "--camera", camera_, "--white", path("white1.png"),
                         path("white2.png"), "--dark", path("dark.png"), "-o", path("white.h5")},
                        out),
            0)
      << out;
  EXPECT_NE(out.find("centres from       the white image"), std::string::npos) << out;
  EXPECT_NE(out.find("frames             0 calibration, 2 white, 1 dark"), std::string::npos) << out;
  EXPECT_NE(out.find("micro-image fill"), std::string::npos) << out;
  const calib::Calibration cal = calib::read_calibration_h5(path("white.h5"));
  EXPECT_EQ(cal.source, calib::CentreSource::white);
  EXPECT_NEAR(cal.spot_lattice.rotation_rad, l.rotation_rad, 2e-4);

  // Refocus a particle 4 mm beyond the focal plane from a float TIFF frame.
  ImageF raw = testing_support::render_particles(cam, truth, {{0.2, -0.1, 4.0, 3e5}}, 200);
  io::write_tiff_stack(path("raw_float.tif"), {raw});
  ASSERT_EQ(run_command({binary("plenopiv"), "refocus", "--camera", camera_, "--calibration", path("white.h5"),
                         path("raw_float.tif"), "--z", "-2:6:2", "-o", path("stack.tif")},
                        out),
            0)
      << out;
  const auto stack = io::read_tiff_stack(path("stack.tif"));
  ASSERT_EQ(stack.size(), 5u);
  for (int k : {0, 1, 2, 4}) EXPECT_GT(peak_share(stack[3]), peak_share(stack[k])) << k;

  // Reconstruct the same particle from an 8-bit PNG frame.
  cv::Mat png(850, 850, CV_8U);
  float top = 0;
  for (float v : raw.pixels) top = std::max(top, v);
  for (int y = 0; y < 850; ++y)
    for (int x = 0; x < 850; ++x) png.at<std::uint8_t>(y, x) = std::uint8_t(std::lround(255 * raw.at(x, y) / top));
  ASSERT_TRUE(cv::imwrite(path("raw.png"), png));
  ASSERT_EQ(run_command({binary("plenopiv"),
                         "reconstruct",
                         "--camera",
                         camera_,
                         path("raw.png"),
                         "--calibration",
                         path("white.h5"),
                         "--extent",
                         "-1",
                         "1",
                         "-1",
                         "1",
                         "2",
                         "6",
                         "--voxel",
                         "0.25",
                         "--iterations",
                         "3",
                         "-o",
                         path("volume.h5")},
                        out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(path("volume.h5")));

  // h5py reads the new parts of the file.
  std::ofstream(path("read.py")) << "import h5py, numpy as np\n"
                                    "f = h5py.File('"
                                 << path("white.h5")
                                 << "', 'r')\n"
                                    "assert f['measured_px'].shape == f['spots_px'].shape\n"
                                    "assert f['uncertainty_px'].shape == f['status'].shape\n"
                                    "assert f['lattice'].attrs['centres_from'] == 1\n"
                                    "assert 0.9 < f['white'].attrs['fill'] < 1.05\n"
                                    "assert set(np.unique(f['status'][()])) <= {0, 1, 2, 3, 4}\n"
                                    "print('ok')\n";
  EXPECT_EQ(run_command({"/usr/bin/python3", path("read.py")}, out), 0) << out;
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
  EXPECT_NE(out.find("flat.tif: calibration image: "), std::string::npos) << out;
  ASSERT_TRUE(cv::imwrite(path("colour.png"), cv::Mat(850, 850, CV_8UC3, cv::Scalar(10, 20, 30))));
  EXPECT_EQ(run_command({binary("plenopiv"), "calibrate", "--camera", camera_, "--white", path("colour.png"), "-o",
                         path("cal.h5")},
                        out),
            2);
  EXPECT_NE(out.find("colour.png: a colour PNG"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(path("cal.h5")));
}

}  // namespace
}  // namespace plenopiv
