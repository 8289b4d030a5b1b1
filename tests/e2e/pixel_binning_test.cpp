// Pixel binning for the reconstruction (reconstruction.pixel_binning): the block mean, the setting's
// range, and a pair through PairProcessor on the binned camera against the simulator's truth.
#include <gtest/gtest.h>

#include <iostream>
#include <string>
#include <vector>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/process/pair_processor.hpp"
#include "core/process/process.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "tests/support/cameras.hpp"
#include "tests/support/input_error.hpp"
#include "tests/support/mean_displacement.hpp"

namespace plenopiv::process {
namespace {

using testing_support::error_of;

TEST(BinPixels, EachPixelIsTheMeanOfItsBlock) {
  ImageF image(6, 4);
  for (std::size_t i = 0; i < image.size(); ++i) image.pixels[i] = float(i * i % 17);
  const ImageF b = bin_pixels(image, 2);
  ASSERT_EQ(b.width, 3);
  ASSERT_EQ(b.height, 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x) {
      const float mean = (image.at(2 * x, 2 * y) + image.at(2 * x + 1, 2 * y) + image.at(2 * x, 2 * y + 1) +
                          image.at(2 * x + 1, 2 * y + 1)) /
                         4;
      EXPECT_FLOAT_EQ(b.at(x, y), mean) << x << " " << y;
    }
  EXPECT_EQ(bin_pixels(image, 1).pixels, image.pixels);
  EXPECT_NE(error_of([&] { bin_pixels(image, 4); }).find("pixel binning 4 does not divide the image's 6 x 4 px"),
            std::string::npos);
  EXPECT_NE(error_of([&] { bin_pixels(image, 0); }), "");
}

const std::string kSpec = R"(
dt_s: 0.0001
volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [0, 4], voxel_mm: 0.125, depth_guard_mm: 1}
correlation:
  passes: [{window: 16, overlap_percent: 50, depth_margin: 4}, {window: 8, overlap_percent: 50}]
  intensity_threshold_of_mean: 4
  depth_prefilter: 4
  final_smoothing: 1
reconstruction: {iterations: 3, mu: 1)";

ProcessSettings parse(const std::string& reconstruction_keys) {
  const std::string text = kSpec + reconstruction_keys + "}\n";
  return process_settings_from(YamlMap(load_yaml_text(text, "run.yaml"), "run.yaml"));
}

TEST(PixelBinning, TheSettingIsOneByDefaultAndRefusedOutsideOneToEight) {
  EXPECT_EQ(parse("").pixel_binning, 1);
  EXPECT_EQ(parse(", pixel_binning: 2").pixel_binning, 2);
  for (const std::string bad : {"0", "9", "-1", "1.5", "two"}) {
    EXPECT_NE(error_of([&] { parse(", pixel_binning: " + bad); }).find("pixel_binning"), std::string::npos) << bad;
  }
}

// The live tier's use: the small camera read 2 x 2 (8.5 px per lens), a pair with a known uniform
// shift through the same PairProcessor every caller uses, against the same pair unbinned.
TEST(PixelBinning, APairOnTheBinnedCameraMeasuresTheShift) {
  const optics::CameraModel camera = testing_support::small_camera();
  const calib::LoadedCalibration calibration = calib::nominal_calibration(camera);
  const sim::Point3 shift{0.25, 0.125, 0.25};  // 2, 1, 2 voxels
  const std::vector<sim::Point3> a = sim::random_particles({{-2.5, -2.5, -0.5}, {2.5, 2.5, 4.5}}, 1600, 21);
  std::vector<sim::Point3> b = a;
  for (auto& p : b)
    for (std::size_t k = 0; k < 3; ++k) p[k] += shift[k];
  sim::RenderOptions ro;
  ro.rays_per_particle = 2000;
  const ImageF frame_a = sim::render(camera, calibration.lenses, a, ro, 3).rays;
  const ImageF frame_b = sim::render(camera, calibration.lenses, b, ro, 4).rays;

  std::array<double, 3> mean[2];
  for (int binning : {1, 2}) {
    const PairProcessor processor(camera, calibration, parse(", pixel_binning: " + std::to_string(binning)));
    EXPECT_EQ(processor.op().weights().image_width(), 850 / binning);
    const PairResult r = processor.process(frame_a, frame_b);
    const VectorField& f = r.correlation.field;
    EXPECT_EQ(r.volume_a.grid, processor.settings().grid);
    const testing_support::MeanDisplacement m = testing_support::mean_displacement(f);
    EXPECT_GT(m.valid, f.grid.count() * 9 / 10) << binning;
    mean[binning - 1] = m.mm;
    std::cout << "measured: binning " << binning << ": mean displacement " << m.mm[0] << " " << m.mm[1] << " "
              << m.mm[2] << " mm (truth " << shift[0] << " " << shift[1] << " " << shift[2] << "), " << m.valid
              << " of " << f.grid.count() << " valid\n";
  }
  // Lateral within 0.01 mm of the truth (measured within 0.004); depth as short as the unbinned
  // camera's (3 iterations: docs/accuracy.md), within 0.03 mm of it (measured 0.008).
  for (std::size_t k = 0; k < 2; ++k) EXPECT_NEAR(mean[1][k], shift[k], 0.01) << k;
  EXPECT_NEAR(mean[1][2], mean[0][2], 0.03);
  EXPECT_GT(mean[1][2], 0.5 * shift[2]);

  // Frames are checked raw, before binning, and named.
  const PairProcessor binned(camera, calibration, parse(", pixel_binning: 2"));
  EXPECT_NE(error_of([&] {
              binned.process(bin_pixels(frame_a, 2), frame_b);
            }).find("frame A: image is 425 x 425 px, the camera's sensor is 850 x 850"),
            std::string::npos);
  ImageF negative = frame_b;
  negative.pixels[10] = -1;
  EXPECT_NE(error_of([&] { binned.process(frame_a, negative); }).find("frame B: pixel (10, 0)"), std::string::npos);
  // A binning that does not divide the sensor names the setting.
  EXPECT_NE(error_of([&] {
              PairProcessor(camera, calibration, parse(", pixel_binning: 3"));
            }).find("reconstruction.pixel_binning: pixel binning 3 does not divide the sensor's 850 x 850 px"),
            std::string::npos);
}

}  // namespace
}  // namespace plenopiv::process
