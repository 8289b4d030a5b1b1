// The ray-traced plenoptic camera checked against geometric optics (paper sec 4, fig 11).
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <stdexcept>
#include <thread>
#include <vector>

#include "core/base/errors.hpp"
#include "core/optics/camera_file.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::sim {
namespace {

// camera-small.yaml: 850 x 850 px behind 50 x 50 lenses, f/2 main lens at M = -1 (matched).
const optics::CameraModel& small_camera() {
  static const optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  return camera;
}
const optics::MicrolensArray& nominal_array() {
  static const optics::MicrolensArray array =
      optics::MicrolensArray::from_lattice(optics::Lattice::nominal(small_camera()));
  return array;
}

double s_i() { return small_camera().image_distance_mm(); }
double f_l() { return small_camera().microlens().focal_length_mm; }

// Where a lens's image is centred on the sensor, in (fractional) pixels.
std::array<double, 2> spot_px(const std::array<double, 2>& centre_mm) {
  const auto& s = small_camera().sensor();
  return {optics::sensor_mm_to_column(s, optics::lens_centre_to_spot_mm(centre_mm[0], s_i(), f_l())),
          optics::sensor_mm_to_row(s, optics::lens_centre_to_spot_mm(centre_mm[1], s_i(), f_l()))};
}

// The object point imaged onto microlens centre c at the focal plane: x_o = c / M.
Point3 on_axis_of(const std::array<double, 2>& c) {
  const double m = small_camera().main_lens().magnification;
  return {c[0] / m, c[1] / m, 0.0};
}

struct Moments {
  double sum = 0, x = 0, y = 0;
};
Moments moments(const ImageF& img) {
  Moments m;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const double v = img.at(x, y);
      m.sum += v;
      m.x += v * x;
      m.y += v * y;
    }
  m.x /= m.sum;
  m.y /= m.sum;
  return m;
}

// Rays per lens of a nominal rect array: each lit pixel goes to the lens whose spot is nearest.
std::map<std::pair<int, int>, Moments> per_lens(const ImageF& img) {
  const auto& cam = small_camera();
  const double spot_pitch_px = cam.pixels_per_microlens() * (1 + f_l() / s_i());
  std::map<std::pair<int, int>, Moments> lenses;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const double v = img.at(x, y);
      if (v == 0) continue;
      const int i = int(std::lround((x - 0.5 * (img.width - 1)) / spot_pitch_px + 0.5 * (cam.microlens().count_x - 1)));
      const int j =
          int(std::lround((y - 0.5 * (img.height - 1)) / spot_pitch_px + 0.5 * (cam.microlens().count_y - 1)));
      Moments& m = lenses[{i, j}];
      m.sum += v;
      m.x += v * x;
      m.y += v * y;
    }
  for (auto& [k, m] : lenses) m.x /= m.sum, m.y /= m.sum;
  return lenses;
}

void expect_accounted(const RayCounts& c) {
  EXPECT_EQ(c.landed + c.outside_sensor + c.missed_array + c.outside_aperture, c.emitted);
}

// Fig 11 top: a particle on a microlens axis at the focal plane lights only that lens's image,
// a disk of the microlens image diameter centred on its spot. Without diffraction the disk is
// sharp; with it (5.2 um = 0.7 px at the sensor) its rim blurs but the light stays on the lens.
void expect_one_lens(const optics::MicrolensArray& array, int i, int j) {
  const auto spot = spot_px(array.centre(i, j));
  const double radius = 0.5 * small_camera().microlens_image_diameter_px();  // 8.45 px
  const Point3 p = on_axis_of(array.centre(i, j));
  for (double sigma : {0.0, 0.0052}) {
    RenderOptions options;
    options.rays_per_particle = 20000;
    options.diffraction_sigma_mm = sigma;
    const RenderResult r = render(small_camera(), array, std::span<const Point3>(&p, 1), options, 4);
    expect_accounted(r.counts);
    EXPECT_EQ(r.counts.landed, r.counts.emitted);
    int lit = 0;
    double farthest = 0, inside = 0;
    for (int y = 0; y < r.rays.height; ++y)
      for (int x = 0; x < r.rays.width; ++x) {
        if (r.rays.at(x, y) == 0) continue;
        ++lit;
        const double d = std::hypot(x - spot[0], y - spot[1]);
        farthest = std::max(farthest, d);
        if (d < radius + 1.5) inside += r.rays.at(x, y);
      }
    if (sigma == 0) {
      // Every lit pixel centre within the disk plus half a pixel diagonal (0.71 px: exact
      // geometry); lit pixels: the disk's 224 px^2 plus its rim.
      EXPECT_LT(farthest, radius + 0.71) << "measured 9.02-9.11 px";
      EXPECT_GT(lit, 200) << "measured 251-255";
      EXPECT_LT(lit, 260) << "measured 251-255";
    } else {
      // Diffraction: the jitter's tails reach the neighbour's rim, nothing more.
      EXPECT_GT(inside / r.counts.landed, 0.99) << "measured 0.998";
      EXPECT_LT(farthest, radius + 3.5) << "measured 10.6-11.0 px";
    }
    const Moments m = moments(r.rays);
    EXPECT_NEAR(m.x, spot[0], 0.1);
    EXPECT_NEAR(m.y, spot[1], 0.1);
  }
}

TEST(Render, InFocusParticleLightsOneMicrolens) { expect_one_lens(nominal_array(), 20, 31); }

TEST(Render, InFocusParticleLightsOneMicrolensOfAnImperfectHexArray) {
  optics::Lattice lattice = optics::Lattice::nominal(small_camera());
  lattice.layout = optics::LensletLayout::hex;
  lattice.pitch_y_mm = lattice.pitch_x_mm * std::sqrt(3.0) / 2;
  lattice.count_x = 48;
  lattice.rotation_rad = 0.01;
  lattice.offset_x_mm = 0.02;
  lattice.offset_y_mm = -0.015;
  const optics::MicrolensArray array = jittered_array(lattice, 0.002, 9);
  expect_one_lens(array, 17, 30);
  expect_one_lens(array, 18, 31);
}

TEST(Render, MainLensInverts) {
  RenderOptions options;
  options.rays_per_particle = 4000;
  const Point3 p{2.0, 1.0, 0.0};  // object +x, +y (right, down)
  const RenderResult r = render(small_camera(), nominal_array(), std::span<const Point3>(&p, 1), options, 1);
  const Moments m = moments(r.rays);
  // Images at x_s = M x (1 + f_l/s_i): left half, upper half of the image (M = -1).
  const auto& s = small_camera().sensor();
  EXPECT_LT(m.x, 0.5 * s.width_px);
  EXPECT_LT(m.y, 0.5 * s.height_px);
  // Lens quantisation: the particle's image lands on the nearest lens; its spot is the centroid.
  EXPECT_NEAR(optics::column_to_sensor_mm(s, m.x), -2.0 * (1 + f_l() / s_i()), 0.5 * 0.125 * 1.005 + 0.01);
  EXPECT_NEAR(optics::row_to_sensor_mm(s, m.y), -1.0 * (1 + f_l() / s_i()), 0.5 * 0.125 * 1.005 + 0.01);
}

// Fig 11 a, b: out of focus, a particle spreads over many lenses, and the sub-images point the
// opposite way for a particle beyond (+z: focus in front of the array, rays cross before it)
// and before (-z: rays caught before they focus) the focal plane.
TEST(Render, DefocusSpreadsOverManyLensesWithOppositePatterns) {
  RenderOptions options;
  options.rays_per_particle = 400000;
  const auto& cam = small_camera();
  for (double dz : {30.0, -30.0}) {
    const Point3 p{0.0, 0.0, dz};
    const RenderResult r = render(cam, nominal_array(), std::span<const Point3>(&p, 1), options, 2);
    expect_accounted(r.counts);
    // The blur on the microlens plane is a disk of radius (p_m / 2) |1 - s_i (1/f_m - 1/d)|,
    // d = s_o + z: 2.885 mm at +30, 5.357 mm at -30 (wider than the 6.25 mm array: the rays
    // beyond it miss; the landed fraction is the square's share of the disk, 0.4330).
    const double d = cam.object_distance_mm() + dz;
    const double blur_r =
        0.5 * cam.aperture_diameter_mm() * std::abs(1 - s_i() * (1 / cam.main_lens().focal_length_mm - 1 / d));
    const auto lenses = per_lens(r.rays);
    EXPECT_GT(lenses.size(), 1000u);
    if (dz > 0) {
      EXPECT_EQ(r.counts.landed, r.counts.emitted);
      // Farthest lit lens centre: within one pitch of the predicted blur radius.
      // (At the blur's rim the sub-images sit on their cell's edge, so some pixels of the next
      // lens out catch light too: hence the one-pitch margin outwards.)
      double far = 0;
      for (const auto& [k, m] : lenses) {
        if (m.sum < 30) continue;
        far = std::max(far, std::hypot(nominal_array().centre(k.first, k.second)[0],
                                       nominal_array().centre(k.first, k.second)[1]));
      }
      EXPECT_GT(far, blur_r - 0.125);
      EXPECT_LT(far, blur_r + 0.25);
    } else {
      const double square = 6.25 * 6.25, disk = std::numbers::pi * blur_r * blur_r;
      // Binomial sd 0.0008 at 4e5 rays.
      EXPECT_NEAR(double(r.counts.landed) / r.counts.emitted, square / disk, 0.004) << "measured 0.4346 against 0.4333";
    }
    // Sub-image offset from its spot against the lens's offset from the blur centre, for lenses
    // well inside the blur (at its rim the sub-images reach the cell edge, see above): all of
    // them along it behind the focal plane, all against it in front.
    int along = 0, against = 0;
    for (const auto& [k, m] : lenses) {
      const auto c = nominal_array().centre(k.first, k.second);
      const double rc = std::hypot(c[0], c[1]);
      if (m.sum < 30 || rc < 0.5 || rc > 0.8 * blur_r) continue;
      const auto spot = spot_px(c);
      const double dot = (m.x - spot[0]) * c[0] + (m.y - spot[1]) * c[1];
      (dot > 0 ? along : against) += 1;
    }
    if (dz > 0) {
      EXPECT_GT(along, 500);
      EXPECT_EQ(against, 0);
    } else {
      EXPECT_GT(against, 500);
      EXPECT_EQ(along, 0);
    }
  }
}

// Fig 11 c, d: a lateral shift of 0.1 mm shifts the pattern; the centroid moves by
// -dy (s_i + f_l) / (s_o + z) on the sensor (mean lens position plus mean slope times f_l).
TEST(Render, LateralShiftShiftsThePattern) {
  RenderOptions options;
  options.rays_per_particle = 100000;
  const auto& cam = small_camera();
  const double dz = 30.0;
  const Point3 a{0.0, 0.0, dz}, b{0.0, 0.1, dz}, c{0.0, -0.1, dz};
  const auto ma = moments(render(cam, nominal_array(), std::span<const Point3>(&a, 1), options, 3).rays);
  const auto mb = moments(render(cam, nominal_array(), std::span<const Point3>(&b, 1), options, 3).rays);
  const auto mc = moments(render(cam, nominal_array(), std::span<const Point3>(&c, 1), options, 3).rays);
  const double expected_px = -0.1 * (s_i() + f_l()) / (cam.object_distance_mm() + dz) / cam.sensor().pixel_pitch_mm;
  // -10.45 px (lens quantisation averages out over many lenses).
  EXPECT_NEAR(mb.y - ma.y, expected_px, 0.1) << "measured -10.47 px";
  EXPECT_NEAR(mc.y - ma.y, -expected_px, 0.1) << "measured +10.45 px";
  EXPECT_NEAR(mb.x - ma.x, 0.0, 0.05);
}

TEST(Render, EveryRayIsAccountedFor) {
  const auto& cam = small_camera();
  RenderOptions options;
  options.rays_per_particle = 40000;
  options.aperture_overfill = 1.25;
  // Centre: only the stop blocks rays, a fraction 1 - 1/1.25^2 = 0.36 (binomial sd 0.0024).
  const Point3 centre{0, 0, 0};
  RenderResult r = render(cam, nominal_array(), std::span<const Point3>(&centre, 1), options, 5);
  expect_accounted(r.counts);
  EXPECT_EQ(r.counts.emitted, 40000u);
  EXPECT_NEAR(double(r.counts.outside_aperture) / r.counts.emitted, 0.36, 0.01);
  EXPECT_EQ(r.counts.missed_array + r.counts.outside_sensor, 0u);
  double sum = 0;
  for (float v : r.rays.pixels) sum += v;
  EXPECT_EQ(sum, double(r.counts.landed));
  // Imaged beside the array: every ray that passes the stop misses the lenses.
  const Point3 beside{3.5, 0, 0};
  r = render(cam, nominal_array(), std::span<const Point3>(&beside, 1), options, 5);
  expect_accounted(r.counts);
  EXPECT_EQ(r.counts.landed, 0u);
  EXPECT_GT(r.counts.missed_array, 20000u);
  // An array shifted over the sensor's edge: the last column's images fall off the sensor.
  optics::Lattice shifted = optics::Lattice::nominal(cam);
  shifted.offset_x_mm = 0.12;
  const auto array = optics::MicrolensArray::from_lattice(shifted);
  const Point3 edge = on_axis_of(array.centre(49, 25));
  r = render(cam, array, std::span<const Point3>(&edge, 1), options, 5);
  expect_accounted(r.counts);
  // The lens's image disk (radius 62.5 um) starts 9 um inside the sensor edge: a sliver lands.
  EXPECT_GT(r.counts.outside_sensor, 20000u) << "measured 24646";
  EXPECT_GT(r.counts.landed, 300u) << "measured 880";
}

TEST(Render, SameSeedSameImageAtAnyThreadCount) {
  const auto& cam = small_camera();
  const auto particles = random_particles(Box{{-3, -3, -5}, {3, 3, 5}}, 300, 17);
  RenderOptions options;
  options.rays_per_particle = 2000;
  options.sensor.shot_noise = true;
  options.sensor.read_noise_electrons = 2;
  RenderResult one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = render(cam, nominal_array(), particles, options, 42);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = render(cam, nominal_array(), particles, options, 42);
  }
  EXPECT_EQ(one.rays.pixels, two.rays.pixels);
  EXPECT_EQ(one.image.pixels, two.image.pixels);
  const RenderResult other = render(cam, nominal_array(), particles, options, 43);
  EXPECT_NE(one.rays.pixels, other.rays.pixels);
}

// Progress is told on the calling thread only, rising to 1; one that throws ends the render: the
// exception reaches render's caller and the tracing stops there, at one thread and at two.
TEST(Render, ProgressIsToldOnTheCallingThreadAndCanEndTheRender) {
  const auto particles = random_particles(Box{{-3, -3, -5}, {3, 3, 5}}, 40000, 17);
  for (const int threads : {1, 2}) {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    RenderOptions options;
    options.rays_per_particle = 20;
    std::vector<double> fractions;
    std::size_t elsewhere = 0;  // reports on another thread
    options.progress = [&, caller = std::this_thread::get_id()](double fraction) {
      fractions.push_back(fraction);
      elsewhere += std::this_thread::get_id() != caller;
    };
    render(small_camera(), nominal_array(), particles, options, 42);
    EXPECT_EQ(elsewhere, 0u) << threads;
    EXPECT_GT(fractions.size(), 10u) << threads;
    EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end())) << threads;
    EXPECT_EQ(fractions.back(), 1.0) << threads;

    fractions.clear();
    options.progress = [&](double fraction) {
      fractions.push_back(fraction);
      if (fraction >= 0.5) throw std::runtime_error("stopped");
    };
    EXPECT_THROW(render(small_camera(), nominal_array(), particles, options, 42), std::runtime_error) << threads;
    // Nothing told after the report that threw (the other thread may have traced on a little
    // meanwhile, so that report's fraction can lie anywhere past a half).
    ASSERT_FALSE(fractions.empty());
    EXPECT_EQ(std::count_if(fractions.begin(), fractions.end(), [](double f) { return f >= 0.5; }), 1) << threads;
  }
}

// Mean of the pixels nearest the midpoints between horizontally adjacent spots, over the mean
// of the pixels nearest the spots, and the same for the corner between four spots.
struct WhiteProfile {
  double edge_ratio = 0, corner_ratio = 0;
};
WhiteProfile white_profile(double f_number) {
  TargetOptions t = white_target();
  t.f_number = f_number;
  t.rays_per_lens = 3000;
  const RenderResult r = render_target(small_camera(), nominal_array(), t, 6);
  expect_accounted(r.counts);
  double centre = 0, edge = 0, corner = 0;
  int n = 0;
  for (int j = 5; j < 45; ++j)
    for (int i = 5; i < 45; ++i) {
      const auto a = spot_px(nominal_array().centre(i, j));
      const auto b = spot_px(nominal_array().centre(i + 1, j));
      const auto c = spot_px(nominal_array().centre(i + 1, j + 1));
      centre += r.rays.at(int(std::lround(a[0])), int(std::lround(a[1])));
      edge += r.rays.at(int(std::lround(0.5 * (a[0] + b[0]))), int(std::lround(a[1])));
      corner += r.rays.at(int(std::lround(0.5 * (a[0] + c[0]))), int(std::lround(0.5 * (a[1] + c[1]))));
      ++n;
    }
  return {edge / centre, corner / centre};
}

TEST(Render, WhiteImageDisksFillTheirCellWithoutSpilling) {
  // Matched (f/2, image side f/4 = the lenses' f/4): the disk reaches the cell edge (edge
  // pixels lit as much as the centre; a spill would add the neighbour's light) and leaves the
  // corners dark.
  const WhiteProfile matched = white_profile(0);
  EXPECT_GT(matched.edge_ratio, 0.8) << "measured 0.93";
  EXPECT_LT(matched.edge_ratio, 1.15) << "measured 0.93";
  EXPECT_LT(matched.corner_ratio, 0.15) << "measured 0.00";
  // Stopped down to f/2.8 the disks shrink (14.2 px < 16.9 px): dark gaps between them.
  EXPECT_LT(white_profile(2.8).edge_ratio, 0.05) << "measured 0.002";
  // Opened to f/1.6 (faster than matching) the disks overlap: the edge gets light twice.
  EXPECT_GT(white_profile(1.6).edge_ratio, 1.6) << "measured 1.99";
}

TEST(Render, CalibrationSpotsSitAtLensCentresSeenFromTheApertureCentre) {
  optics::Lattice lattice = optics::Lattice::nominal(small_camera());
  lattice.rotation_rad = -0.004;
  lattice.offset_x_mm = 0.011;
  const optics::MicrolensArray array = jittered_array(lattice, 0.003, 21);
  TargetOptions t = calibration_target();
  t.rays_per_lens = 3000;
  const RenderResult r = render_target(small_camera(), array, t, 7);
  double worst = 0;
  for (int j = 1; j < 49; ++j)
    for (int i = 1; i < 49; ++i) {
      const auto spot = spot_px(array.centre(i, j));
      double s = 0, sx = 0, sy = 0;
      for (int y = int(spot[1]) - 4; y <= int(spot[1]) + 5; ++y)
        for (int x = int(spot[0]) - 4; x <= int(spot[0]) + 5; ++x) {
          const double v = r.rays.at(x, y);
          s += v;
          sx += v * x;
          sy += v * y;
        }
      ASSERT_GT(s, 0);
      worst = std::max(worst, std::hypot(sx / s - spot[0], sy / s - spot[1]));
    }
  // Spot of f/16: 2.1 px across; the centroid of whole pixels lies within 0.15 px of the true
  // spot.
  EXPECT_LT(worst, 0.15) << "measured 0.063 px worst over 48 x 48 lenses at 3000 rays per lens";
}

TEST(Render, SensorModel) {
  ImageF flat(64, 64, 100.f);
  SensorModel s;
  s.gain_dn_per_electron = 2;
  s.dark_offset_dn = 10;
  s.bit_depth = 8;
  ImageU16 out = apply_sensor(flat, s, 1);
  EXPECT_EQ(out.at(3, 3), 210);
  flat.at(0, 0) = 1000;
  EXPECT_EQ(apply_sensor(flat, s, 1).at(0, 0), 255);  // saturates at 2^8 - 1
  SensorModel noisy;
  noisy.shot_noise = true;
  noisy.read_noise_electrons = 5;
  out = apply_sensor(ImageF(200, 200, 100.f), noisy, 2);
  double mean = 0, var = 0;
  for (auto v : out.pixels) mean += v;
  mean /= out.size();
  for (auto v : out.pixels) var += (v - mean) * (v - mean);
  var /= out.size() - 1;
  // Poisson variance 100 + read 25 (+ 1/12 rounding); sd of the estimate ~0.9.
  EXPECT_NEAR(mean, 100, 0.3) << "measured 100.008";
  EXPECT_NEAR(var, 125.08, 4) << "measured 126.2";
  // A second tap's offset: the right half as if its pedestal were that much higher, the same noise.
  SensorModel one_tap = noisy;
  one_tap.dark_offset_dn = 20;
  SensorModel two_taps = one_tap, higher = one_tap;
  two_taps.right_half_offset_dn = 30;
  higher.dark_offset_dn = 50;
  const ImageF lit(200, 200, 100.f);
  const ImageU16 taps = apply_sensor(lit, two_taps, 2), left = apply_sensor(lit, one_tap, 2),
                 right = apply_sensor(lit, higher, 2);
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 200; ++x) ASSERT_EQ(taps.at(x, y), (x < 100 ? left : right).at(x, y)) << x << ", " << y;
  SensorModel bad;
  bad.bit_depth = 17;
  EXPECT_THROW(apply_sensor(flat, bad, 1), InputError);
  bad = SensorModel{};
  bad.right_half_offset_dn = -1;
  EXPECT_THROW(apply_sensor(flat, bad, 1), InputError);
}

TEST(Render, ParticlesDifferInBrightnessAndKeepItInBothFrames) {
  const auto& cam = small_camera();
  const Point3 centre{0, 0, 0};
  RenderOptions options;
  options.rays_per_particle = 1000;
  options.brightness_spread = 1.0;
  // One particle under 200 brightness seeds: its rays are 1000 times a log-normal factor, whose
  // log has mean -s^2 / 2 and spread s (standard errors 0.07 and 0.05 at 200 draws; the bounds
  // are 3.5 and 3 of them).
  double sum_log = 0, sum_log2 = 0;
  const int draws = 200;
  for (int k = 0; k < draws; ++k) {
    options.brightness_seed = std::uint64_t(k);
    const RenderResult r = render(cam, nominal_array(), std::span<const Point3>(&centre, 1), options, 5);
    ASSERT_GT(r.counts.emitted, 0u);
    const double l = std::log(double(r.counts.emitted) / 1000.0);
    sum_log += l;
    sum_log2 += l * l;
  }
  const double mean = sum_log / draws, spread = std::sqrt(sum_log2 / draws - mean * mean);
  EXPECT_NEAR(mean, -0.5, 0.25) << "measured -0.654";
  EXPECT_NEAR(spread, 1.0, 0.15) << "measured 0.951";

  // A pair: the frames' own seeds differ, each particle's light does not.
  const auto particles = random_particles(Box{{-3, -3, -5}, {3, 3, 5}}, 400, 3);
  options.brightness_seed = 7;
  const RenderResult a = render(cam, nominal_array(), particles, options, 1);
  const RenderResult b = render(cam, nominal_array(), particles, options, 2);
  EXPECT_EQ(a.counts.emitted, b.counts.emitted);
  EXPECT_NE(a.rays.pixels, b.rays.pixels);
  EXPECT_NEAR(double(a.counts.emitted) / (400.0 * 1000.0), 1.0, 0.25);  // a mean of 1 (sd 0.07 at 400)
  options.brightness_seed = 8;
  EXPECT_NE(render(cam, nominal_array(), particles, options, 1).counts.emitted, a.counts.emitted);

  // No spread: every particle its rays_per_particle, the image as without the option.
  options.brightness_spread = 0;
  const RenderResult same = render(cam, nominal_array(), particles, options, 1);
  EXPECT_EQ(same.counts.emitted, 400u * 1000u);
  RenderOptions plain;
  plain.rays_per_particle = 1000;
  EXPECT_EQ(same.rays.pixels, render(cam, nominal_array(), particles, plain, 1).rays.pixels);
}

TEST(Render, BadInputIsRefused) {
  RenderOptions options;
  const Point3 behind{0, 0, -150};
  EXPECT_THROW(render(small_camera(), nominal_array(), std::span<const Point3>(&behind, 1), options, 1), InputError);
  const Point3 nan{std::nan(""), 0, 0};
  EXPECT_THROW(render(small_camera(), nominal_array(), std::span<const Point3>(&nan, 1), options, 1), InputError);
  options.diffraction_sigma_mm = -1;
  const Point3 ok{0, 0, 0};
  EXPECT_THROW(render(small_camera(), nominal_array(), std::span<const Point3>(&ok, 1), options, 1), InputError);
  for (double spread : {-0.1, 3.5, std::nan("")}) {
    RenderOptions bright;
    bright.brightness_spread = spread;
    EXPECT_THROW(render(small_camera(), nominal_array(), std::span<const Point3>(&ok, 1), bright, 1), InputError)
        << spread;
  }
}

}  // namespace
}  // namespace plenopiv::sim
