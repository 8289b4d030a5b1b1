// Each raw frame's black level (reconstruction.black_level): where BlackLevelMeter reads it, the
// setting, and a pair with a sensor pedestal through PairProcessor against the simulator's truth.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <iostream>
#include <string>
#include <vector>

#include "core/base/yaml_access.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/process/black_level.hpp"
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

// A white correction of disks of radius 4 px on a 10 px lattice (1 inside, 0 outside), 80 x 80 px.
ImageF disk_white() {
  ImageF white(80, 80);
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x) {
      const double dx = x % 10 - 4.5, dy = y % 10 - 4.5;
      white.at(x, y) = dx * dx + dy * dy <= 16 ? 1.f : 0.f;
    }
  return white;
}

bool beside_light(const ImageF& white, int x, int y) {
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int u = x + dx, v = y + dy;
      if (u < 0 || v < 0 || u >= white.width || v >= white.height || white.at(u, v) != 0.f) return true;
    }
  return false;
}

TEST(BlackLevelMeter, ReadsTheMedianBetweenTheImagesAndNotBesideThem) {
  const ImageF white = disk_white();
  const BlackLevelMeter meter(white);
  EXPECT_GE(meter.samples(), BlackLevelMeter::kMinSamples);
  EXPECT_EQ(meter.samples(), meter.candidates());  // fewer than kMaxSamples: every one kept
  // Pedestal 50 with a symmetric spread between the images; far brighter light in the images and
  // on every pixel beside them (a particle's image blurred by diffraction), which must not count.
  ImageF frame(white.width, white.height);
  ImageU16 counts(white.width, white.height);
  int k = 0;
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x) {
      const float v = beside_light(white, x, y) ? 1000.f : float(50 + (k++ % 5) - 2);
      frame.at(x, y) = v;
      counts.at(x, y) = std::uint16_t(v);
    }
  // 80 x 80 px hold too few such pixels for tiles of their own: the sensor is one tile.
  EXPECT_EQ(meter.tiles_x(), 1);
  EXPECT_EQ(meter.tiles_y(), 1);
  EXPECT_EQ(meter.measure(frame).level, std::vector<float>{50.f});
  EXPECT_EQ(meter.measure(counts).level, std::vector<float>{50.f});
  EXPECT_EQ(meter.measure(frame).text(), "50");
  EXPECT_NE(meter.describe().find("median over " + std::to_string(meter.samples())), std::string::npos)
      << meter.describe();  // A frame of another size is named, not read past its end.
  EXPECT_NE(
      error_of([&] { meter.measure(ImageF(40, 80)); }).find("the frame is 40 x 80 px, the white correction 80 x 80"),
      std::string::npos);
}

TEST(BlackLevelMeter, WithoutPixelsBetweenTheImagesItMeasuresNothingAndSaysSo) {
  ImageF white(80, 80);
  for (float& w : white.pixels) w = 1.f;
  const BlackLevelMeter meter(white);
  EXPECT_EQ(meter.samples(), 0u);
  ImageF frame(80, 80);
  for (float& v : frame.pixels) v = 70.f;
  EXPECT_FALSE(meter.measure(frame).measured());
  EXPECT_EQ(meter.measure(frame).median(), 0.f);
  EXPECT_NE(meter.describe().find("not measured"), std::string::npos) << meter.describe();
  EXPECT_NE(meter.describe().find("reconstruction.black_level: none"), std::string::npos) << meter.describe();
}

TEST(SubtractBlackLevel, TakesTheLevelOffAndClampsAtZero) {
  ImageF frame(4, 1);
  frame.pixels = {0.f, 19.5f, 20.f, 120.f};
  ImageF same = frame;
  subtract_black_level(same, BlackLevels{});
  EXPECT_EQ(same.pixels, frame.pixels);
  subtract_black_level(same, BlackLevels::uniform(4, 1, 0.f));
  EXPECT_EQ(same.pixels, frame.pixels);
  subtract_black_level(frame, BlackLevels::uniform(4, 1, 20.f));
  EXPECT_EQ(frame.pixels, (HugePageVector<float>{0.f, 0.f, 0.f, 100.f}));
  const std::string e = error_of([&] { subtract_black_level(frame, BlackLevels::uniform(6, 1, 20.f)); });
  EXPECT_NE(e.find("the frame is 4 x 1 px, neither the sensor's 6 x 1 nor its pixels binned"), std::string::npos) << e;
}

// A sensor read out through two taps with different offsets: left half 20 counts, right half 50.
// Each tile's own median goes where it was measured; one median over the sensor suits one half
// at most.
TEST(BlackLevelMeter, TakesEachTapsOffsetOffItsOwnHalf) {
  ImageF white(400, 200);
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x) {
      const double dx = x % 10 - 4.5, dy = y % 10 - 4.5;
      white.at(x, y) = dx * dx + dy * dy <= 16 ? 1.f : 0.f;
    }
  const BlackLevelMeter meter(white);
  EXPECT_EQ(meter.tiles_x(), 2);
  EXPECT_EQ(meter.tiles_y(), 2);
  EXPECT_NE(meter.describe().find("in each of 2 x 2 tiles"), std::string::npos) << meter.describe();
  ImageF frame(white.width, white.height);
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x)
      frame.at(x, y) = (x < white.width / 2 ? 20.f : 50.f) + (beside_light(white, x, y) ? 1000.f : 0.f);
  const BlackLevels levels = meter.measure(frame);
  EXPECT_EQ(levels.level, (std::vector<float>{20.f, 50.f, 20.f, 50.f}));
  EXPECT_EQ(levels.lowest(), 20.f);
  EXPECT_EQ(levels.highest(), 50.f);
  EXPECT_EQ(levels.text(), "50 (20 to 50 over 2 x 2 tiles)");
  // Binned 2 x 2 (the live tier's frames): each binned pixel takes its block's tile.
  ImageF binned(white.width / 2, white.height / 2);
  for (int y = 0; y < binned.height; ++y)
    for (int x = 0; x < binned.width; ++x) binned.at(x, y) = x < binned.width / 2 ? 20.f : 50.f;
  subtract_black_level(binned, levels);
  for (const float v : binned.pixels) ASSERT_EQ(v, 0.f);
  subtract_black_level(frame, levels);
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x) ASSERT_EQ(frame.at(x, y), beside_light(white, x, y) ? 1000.f : 0.f);
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

TEST(BlackLevel, TheSettingIsBetweenImagesByDefaultAndAnUnknownNameIsRefused) {
  EXPECT_EQ(parse("").black_level, BlackLevel::between_images);
  EXPECT_EQ(parse(", black_level: none").black_level, BlackLevel::none);
  EXPECT_EQ(parse(", black_level: between_images").black_level, BlackLevel::between_images);
  const std::string e = error_of([&] { parse(", black_level: 100"); });
  EXPECT_NE(e.find("black_level"), std::string::npos) << e;
  EXPECT_NE(e.find("between_images"), std::string::npos) << e;
  EXPECT_NE(settings_key(parse("")), settings_key(parse(", black_level: none")));
}

// A uniform shift of (2, 1, 2) voxels.
const sim::Point3 kShift{0.25, 0.125, 0.25};

// The small camera and 1600 particles moved by kShift, rendered with the simulator's one count
// per ray and through a sensor with a pedestal (the simulated camera's response with a 100-count
// offset, 2 e of read noise), its right half `second_tap` counts higher.
struct SmallPair {
  optics::CameraModel camera = testing_support::small_camera();
  calib::LoadedCalibration calibration = calib::nominal_calibration(camera);
  sim::RenderResult clean_a, clean_b;
  ImageU16 sensor_a, sensor_b;
};

SmallPair small_pair(double second_tap = 0) {
  SmallPair pair;
  const std::vector<sim::Point3> a = sim::random_particles({{-2.5, -2.5, -0.5}, {2.5, 2.5, 4.5}}, 1600, 21);
  std::vector<sim::Point3> b = a;
  for (auto& p : b)
    for (std::size_t k = 0; k < 3; ++k) p[k] += kShift[k];
  sim::RenderOptions ro;
  ro.rays_per_particle = 2000;
  pair.clean_a = sim::render(pair.camera, pair.calibration.lenses, a, ro, 3);
  pair.clean_b = sim::render(pair.camera, pair.calibration.lenses, b, ro, 4);
  ro.sensor.electrons_per_ray = 4;
  ro.sensor.shot_noise = true;
  ro.sensor.read_noise_electrons = 2;
  ro.sensor.dark_offset_dn = 100;
  ro.sensor.right_half_offset_dn = second_tap;
  ro.sensor.bit_depth = 12;
  pair.sensor_a = sim::render(pair.camera, pair.calibration.lenses, a, ro, 3).image;
  pair.sensor_b = sim::render(pair.camera, pair.calibration.lenses, b, ro, 4).image;
  return pair;
}

// The largest component error of the pair's mean displacement against kShift, mm; printed with
// `name`.
double shift_error(const PairResult& r, const char* name) {
  const testing_support::MeanDisplacement m = testing_support::mean_displacement(r.correlation.field);
  double e = 0;
  for (std::size_t k = 0; k < 3; ++k) e = std::max(e, std::abs(m.mm[k] - kShift[k]));
  std::cout << "measured: " << name << ": mean displacement " << m.mm[0] << " " << m.mm[1] << " " << m.mm[2]
            << " mm (truth 0.25 0.125 0.25), " << m.valid << " of " << r.correlation.field.grid.count()
            << " valid, largest component error " << e << " mm; voxel updates skipped "
            << 100 * r.skipped_a.fraction_updates_skipped() << " %\n";
  return e;
}

// The pair with its sensor's pedestal taken off measures the shift as the clean one does; left
// on, MART takes the pedestal for light in every voxel.
TEST(BlackLevel, APedestalIsTakenOffAndThePairMeasuresTheShift) {
  const SmallPair pair = small_pair();
  const optics::CameraModel& camera = pair.camera;
  const calib::LoadedCalibration& calibration = pair.calibration;
  const sim::RenderResult& clean_a = pair.clean_a;
  const sim::RenderResult& clean_b = pair.clean_b;
  const ImageU16& noisy_a = pair.sensor_a;
  const ImageU16& noisy_b = pair.sensor_b;

  const PairProcessor taken_off(camera, calibration, parse(""));
  const PairProcessor left_on(camera, calibration, parse(", black_level: none"));
  EXPECT_NE(taken_off.black_level_note().find("median over"), std::string::npos) << taken_off.black_level_note();
  EXPECT_NE(left_on.black_level_note().find("none taken off"), std::string::npos) << left_on.black_level_note();

  // One count per ray: nothing between the images, nothing taken off, the same bits either way.
  const PairResult clean = taken_off.process(clean_a.rays, clean_b.rays);
  const PairResult clean_none = left_on.process(clean_a.rays, clean_b.rays);
  EXPECT_EQ(clean.black_level_a.highest(), 0.f);
  EXPECT_EQ(clean.black_level_b.highest(), 0.f);
  EXPECT_EQ(clean.volume_a.data, clean_none.volume_a.data);
  EXPECT_EQ(clean.correlation.field.dz_mm, clean_none.correlation.field.dz_mm);

  const PairResult off = taken_off.process(noisy_a, noisy_b);
  const PairResult on = left_on.process(noisy_a, noisy_b);
  EXPECT_NEAR(off.black_level_a.lowest(), 100.f, 1.f);
  EXPECT_NEAR(off.black_level_a.highest(), 100.f, 1.f);
  EXPECT_NEAR(off.black_level_b.median(), 100.f, 1.f);
  EXPECT_FALSE(on.black_level_a.measured());

  const double e_clean = shift_error(clean, "one count per ray");
  const double e_off = shift_error(off, "pedestal taken off");
  const double e_on = shift_error(on, "pedestal left on");
  EXPECT_LT(e_off, e_clean + 0.02);  // measured 0.004 mm more
  EXPECT_GT(e_on, e_off + 0.1);      // measured 0.18 mm more
  EXPECT_GT(off.skipped_a.fraction_updates_skipped(), on.skipped_a.fraction_updates_skipped() + 0.2);

  // Read 2 x 2 (the live tier's binning): the level is measured on the raw counts and taken off
  // the binned frames.
  const PairProcessor binned(camera, calibration, parse(", pixel_binning: 2"));
  const PairResult b2 = binned.process(noisy_a, noisy_b);
  EXPECT_EQ(b2.black_level_a.level, off.black_level_a.level);
  EXPECT_EQ(b2.black_level_b.level, off.black_level_b.level);
  const double e_binned = shift_error(b2, "pedestal taken off, pixels binned 2 x 2");
  const double e_binned_clean =
      shift_error(binned.process(clean_a.rays, clean_b.rays), "one count per ray, binned 2 x 2");
  EXPECT_LT(e_binned, e_binned_clean + 0.04);  // measured 0.016 mm more (w); left on: 0.25 mm
}

// The same pair through a sensor read out in two halves whose offsets differ by 40 counts (100
// and 140): each half's own level taken off, the pair measures the shift as the clean one does;
// one median over the whole sensor leaves 40 counts of pedestal on one half or clamps 40 counts
// of light off the other.
TEST(BlackLevel, ATwoTapSensorsOffsetsAreTakenOffHalfByHalf) {
  const SmallPair pair = small_pair(40);
  const calib::LoadedCalibration& calibration = pair.calibration;
  const ImageU16 &taps_a = pair.sensor_a, &taps_b = pair.sensor_b;

  const PairProcessor taken_off(pair.camera, calibration, parse(""));
  const PairResult clean = taken_off.process(pair.clean_a.rays, pair.clean_b.rays);
  const PairResult tiles = taken_off.process(taps_a, taps_b);
  EXPECT_EQ(tiles.black_level_a.tiles_x % 2, 0);
  EXPECT_NEAR(tiles.black_level_a.lowest(), 100.f, 1.f);
  EXPECT_NEAR(tiles.black_level_a.highest(), 140.f, 1.f);
  EXPECT_NE(tiles.black_level_a.text().find(" tiles)"), std::string::npos) << tiles.black_level_a.text();

  // One level for the whole sensor: the median of the pixels between the images, both halves.
  const auto one_level = [&](const ImageU16& frame) {
    std::vector<float> between;
    const ImageF& white = calibration.white_correction;
    for (int y = 1; y + 1 < white.height; ++y)
      for (int x = 1; x + 1 < white.width; ++x)
        if (!beside_light(white, x, y)) between.push_back(float(frame.at(x, y)));
    std::nth_element(between.begin(), between.begin() + std::ptrdiff_t(between.size() / 2), between.end());
    ImageF f = to_float(frame);
    subtract_black_level(f, BlackLevels::uniform(f.width, f.height, between[between.size() / 2]));
    return f;
  };
  const PairProcessor as_recorded(pair.camera, calibration, parse(", black_level: none"));
  const PairResult one = as_recorded.process(one_level(taps_a), one_level(taps_b));

  const double e_clean = shift_error(clean, "one count per ray");
  const double e_tiles = shift_error(tiles, "two taps, each tile's level taken off");
  const double e_one = shift_error(one, "two taps, one level for the sensor taken off");
  EXPECT_LT(e_tiles, e_clean + 0.02);  // measured 0.004 mm more, as for one offset
  EXPECT_GT(e_one, e_tiles + 0.02);    // measured 0.034 mm more (w short)
}

}  // namespace
}  // namespace plenopiv::process
