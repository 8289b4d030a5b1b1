// MART's depth response (process::DepthResponse): the per-layer inverse, its refusals, the
// setting, its bytes and disk cache, its progress, and a shear pair on the small camera whose w it
// brings nearer the truth.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/base/build_info.hpp"
#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/process/depth_response.hpp"
#include "core/process/operator_cache.hpp"
#include "core/process/pair_processor.hpp"
#include "core/process/process.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "tests/support/cameras.hpp"
#include "tests/support/input_error.hpp"
#include "tests/support/shallow_spec.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::process {
namespace {

using testing_support::error_of;

Grid3 two_layers() {
  Grid3 g;
  g.shape = {2, 1, 2};
  g.origin_mm = {0, 0, -3};
  g.spacing_mm = {1, 1, 6};
  return g;
}

const std::vector<double> kShifts{-0.25, -0.125, 0, 0.125, 0.25};

TEST(DepthResponse, InvertsEachLayersCurvePiecewiseAndGoesOnAlongItsEndSegments) {
  // Layer 0 measures 0.8 of every shift; layer 1 less towards +z than towards -z.
  const DepthResponse r(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, {-0.24, -0.12, 0, 0.1, 0.18}});
  for (std::size_t k = 0; k < kShifts.size(); ++k) {
    EXPECT_NEAR(r.true_mm(0, 0.8 * kShifts[k]), kShifts[k], 1e-12) << k;
    EXPECT_NEAR(r.true_mm(1, r.measured_mm()[1][k]), kShifts[k], 1e-12) << k;
  }
  EXPECT_NEAR(r.slope(0, 0.05), 1.25, 1e-12);
  EXPECT_NEAR(r.true_mm(1, 0.05), 0.0625, 1e-12);        // half way up the first segment above 0
  EXPECT_NEAR(r.true_mm(1, 0.14), 0.1875, 1e-12);        // half way up the last
  EXPECT_NEAR(r.true_mm(1, 0.26), 0.25 + 0.125, 1e-12);  // beyond it, along it
  EXPECT_NEAR(r.slope(1, 0.26), 0.125 / 0.08, 1e-12);
  EXPECT_NEAR(r.true_mm(1, -0.36), -0.25 - 0.125, 1e-12);  // below the first, along it
  EXPECT_NEAR(r.slope(1, -0.06), 0.125 / 0.12, 1e-12);

  VectorField f(two_layers());
  f.dz_mm = {0.1f, NAN, 0.05f, -0.06f};
  f.dx_mm = {1, 2, 3, 4};
  f.sigma_dz_mm = {0.02f, NAN, 0.02f, 0.01f};
  f.sigma_dx_mm = f.sigma_dy_mm = {0.01f, NAN, 0.01f, 0.01f};
  const VectorField before = f;
  r.apply(f);
  EXPECT_FLOAT_EQ(f.dz_mm[0], 0.125f);
  EXPECT_TRUE(std::isnan(f.dz_mm[1]));
  EXPECT_FLOAT_EQ(f.dz_mm[2], 0.0625f);
  EXPECT_FLOAT_EQ(f.dz_mm[3], -0.0625f);
  EXPECT_FLOAT_EQ(f.sigma_dz_mm[0], 0.025f);
  EXPECT_FLOAT_EQ(f.sigma_dz_mm[2], 0.025f);
  EXPECT_FLOAT_EQ(f.sigma_dz_mm[3], float(0.01 * 0.125 / 0.12));
  EXPECT_EQ(f.dx_mm, before.dx_mm);  // lateral components untouched, and their sigma: none unseen
  EXPECT_EQ(f.sigma_dx_mm[0], before.sigma_dx_mm[0]);

  Grid3 other = two_layers();
  other.origin_mm[2] = -2;
  VectorField elsewhere(other);
  EXPECT_THROW(r.apply(elsewhere), std::logic_error);
  EXPECT_NE(r.summary().find("0.72..0.8 of +0.25 mm"), std::string::npos) << r.summary();
}

// The error the correlation's sigma leaves out, per layer: u's and v's sigma scaled, w's unseen
// error added in quadrature before its inverse's slope; no estimate (NaN) stays none.
TEST(DepthResponse, WidensEachSigmaAsItsLayerSays) {
  const DepthResponse r(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, {-0.24, -0.12, 0, 0.1, 0.18}},
                        {{1.25, 1.0, 0.015}, {1.0, 5.0 / 3, 0.0}});
  VectorField f(two_layers());
  f.dz_mm = {0.1f, 0.1f, 0.05f, 0.05f};
  f.sigma_dx_mm = {0.04f, NAN, 0.03f, 0.02f};
  f.sigma_dy_mm = {0.01f, NAN, 0.03f, 0.02f};
  f.sigma_dz_mm = {0.02f, NAN, 0.02f, 0.01f};
  f.sigma_method = "correlation statistics";
  r.apply(f);
  EXPECT_EQ(f.sigma_method.rfind("correlation statistics; widened per depth layer", 0), 0u) << f.sigma_method;
  EXPECT_NE(f.sigma_method.find("MART's depth response"), std::string::npos) << f.sigma_method;
  EXPECT_FLOAT_EQ(f.sigma_dx_mm[0], 0.05f);  // layer 0: 0.04 x 1.25
  EXPECT_FLOAT_EQ(f.sigma_dy_mm[0], 0.01f);
  EXPECT_FLOAT_EQ(f.sigma_dz_mm[0], 0.025f * 1.25f);  // hypot(0.02, 0.015), then slope 1.25
  EXPECT_TRUE(std::isnan(f.sigma_dx_mm[1]) && std::isnan(f.sigma_dy_mm[1]) && std::isnan(f.sigma_dz_mm[1]));
  EXPECT_FLOAT_EQ(f.sigma_dx_mm[2], 0.03f);  // layer 1: 0.03 x 5 / 3 in v only
  EXPECT_FLOAT_EQ(f.sigma_dy_mm[2], 0.05f);
  EXPECT_FLOAT_EQ(f.sigma_dz_mm[2], 0.025f);
  EXPECT_NE(r.summary().find("u up to x1.25, v up to x1.67, w by up to 0.015 mm"), std::string::npos) << r.summary();

  // One per layer; scales finite and at least 1 (never narrower), w's unseen error finite and not negative.
  const auto widen = [](std::vector<SigmaWidening> w) {
    DepthResponse(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, {-0.2, -0.1, 0, 0.1, 0.2}}, std::move(w));
  };
  EXPECT_THROW(widen({{1, 1, 0}}), std::logic_error);
  EXPECT_THROW(widen({{1, 1, 0}, {1, 0.99, 0}}), std::logic_error);
  EXPECT_THROW(widen({{NAN, 1, 0}, {1, 1, 0}}), std::logic_error);
  EXPECT_THROW(widen({{1, 1, -0.01}, {1, 1, 0}}), std::logic_error);
  EXPECT_THROW(widen({{1, 1, NAN}, {1, 1, 0}}), std::logic_error);
  EXPECT_NO_THROW(widen({{1, 1, 0}, {2, 3, 0.1}}));
  EXPECT_NO_THROW(widen({}));
}

TEST(DepthResponse, RefusesALayerWhoseVectorsBarelyFollowTheShift) {
  // Layer 1 (z = 3 mm) measures the same for two shifts: no inverse.
  const auto refused = [](std::vector<double> layer_1) {
    return error_of([&] { DepthResponse(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, layer_1}); });
  };
  const std::string e = refused({-0.2, -0.1, 0, 0.1, 0.1});
  EXPECT_NE(e.find("the vectors at z = 3 mm follow a depth shift by less than 0.333 of it"), std::string::npos) << e;
  EXPECT_NE(e.find("0.25 -> 0.1"), std::string::npos) << e;
  EXPECT_NE(e.find("would multiply its noise by more than 3;"), std::string::npos) << e;
  EXPECT_NE(refused({-0.2, -0.1, 0, 0.1, NAN}).find("z = 3 mm"), std::string::npos);
  EXPECT_NE(refused({-0.2, -0.1, 0, 0.1, 0.05}).find("z = 3 mm"), std::string::npos);  // falls back
  // Measuring just under a third of an outermost shift (either way) is refused; a third, kept.
  EXPECT_NE(refused({-0.2, -0.05, 0, 0.05, 0.0833}).find("z = 3 mm"), std::string::npos);
  EXPECT_EQ(refused({-0.2, -0.05, 0, 0.05, 0.0834}), "");
  EXPECT_NE(refused({-0.0833, -0.05, 0, 0.05, 0.2}).find("z = 3 mm"), std::string::npos);
  EXPECT_EQ(refused({-0.0834, -0.05, 0, 0.05, 0.2}), "");
}

TEST(DepthResponse, AnInnerShiftMeasuredAsLessThanAThirdIsTakenAsAThird) {
  // Layer 1 follows the outermost shifts but locks the inner ones (0.2 and 0.16 of them).
  const DepthResponse r(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, {-0.2, -0.025, 0, 0.02, 0.2}});
  EXPECT_EQ(r.measured_mm()[1], (std::vector<double>{-0.2, -0.025, 0, 0.02, 0.2}));  // kept as measured
  const double third = 0.125 / 3;
  EXPECT_EQ(r.curve_mm()[1], (std::vector<double>{-0.2, -third, 0, third, 0.2}));
  EXPECT_EQ(r.curve_mm()[0], r.measured_mm()[0]);
  // The inverse's slope about 0 is 3, not 6.25: a measured 0.02 comes out 0.06, under-corrected.
  EXPECT_NEAR(r.slope(1, 0.02), 3, 1e-12);
  EXPECT_NEAR(r.true_mm(1, 0.02), 0.06, 1e-12);
  EXPECT_NEAR(r.true_mm(1, 0.2), 0.25, 1e-12);  // the outermost shifts as measured
  EXPECT_NEAR(r.true_mm(1, -0.2), -0.25, 1e-12);
  const std::string summary = r.summary();
  EXPECT_NE(summary.find("2 inner shifts over z 3..3 mm measured as less than 0.333 of it, taken as that"),
            std::string::npos)
      << summary;
  // Its bytes hold what was measured, and read back to the same curve and summary.
  std::string bytes;
  r.serialize(bytes);
  const DepthResponse back = DepthResponse::deserialize(bytes);
  EXPECT_EQ(back.measured_mm(), r.measured_mm());
  EXPECT_EQ(back.curve_mm(), r.curve_mm());
  EXPECT_EQ(back.summary(), summary);
  // A response with none raised says nothing of it.
  EXPECT_EQ(DepthResponse(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, {-0.2, -0.1, 0, 0.1, 0.2}})
                .summary()
                .find("inner shift"),
            std::string::npos);
}

TEST(DepthResponse, ItsBytesReadBackTheSameAndDamagedOnesAreRefused) {
  const DepthResponse r(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, {-0.24, -0.12, 0, 0.1, 0.18}},
                        {{1.1, 1.2, 0.03}, {1.4, 1.5, 0.06}});
  std::string bytes;
  r.serialize(bytes);
  const DepthResponse back = DepthResponse::deserialize(bytes);
  EXPECT_EQ(back.field_grid(), r.field_grid());
  EXPECT_EQ(back.shifts_mm(), r.shifts_mm());
  EXPECT_EQ(back.measured_mm(), r.measured_mm());
  EXPECT_EQ(back.sigma_widening(), r.sigma_widening());
  // Without a widening (a processing that estimates no sigma): an empty array, read back empty.
  const DepthResponse none(two_layers(), kShifts, r.measured_mm());
  std::string none_bytes;
  none.serialize(none_bytes);
  EXPECT_TRUE(DepthResponse::deserialize(none_bytes).sigma_widening().empty());
  for (std::size_t cut = 0; cut < bytes.size(); cut += 7) {
    const std::string e = error_of([&] { DepthResponse::deserialize(std::string_view(bytes).substr(0, cut)); });
    EXPECT_NE(e.find("depth response bytes: "), std::string::npos) << cut << ": " << e;
  }
  EXPECT_NE(error_of([&] { DepthResponse::deserialize(bytes + "x"); }).find("bytes left"), std::string::npos);
  // A measured value that no longer rises, or a negative unseen w: what the constructor refuses, named.
  const std::size_t widening_bytes = sizeof(std::uint64_t) + 2 * sizeof(SigmaWidening);
  std::string flat = bytes;
  const double same = 0.1;
  std::memcpy(flat.data() + flat.size() - widening_bytes - sizeof(double), &same, sizeof same);
  EXPECT_NE(error_of([&] { DepthResponse::deserialize(flat); }).find("the vectors at z = 3 mm"), std::string::npos);
  std::string negative = bytes;
  const double below = -0.01;
  std::memcpy(negative.data() + negative.size() - sizeof(double), &below, sizeof below);
  EXPECT_NE(error_of([&] { DepthResponse::deserialize(negative); }).find("its unseen w finite and not negative"),
            std::string::npos);
  // A layer count the bytes cannot hold is refused before anything is allocated for it.
  std::string many = bytes;
  const int layers = 1 << 30;
  std::memcpy(many.data() + 2 * sizeof(int), &layers, sizeof layers);
  EXPECT_NE(error_of([&] { DepthResponse::deserialize(many); }).find("depth layers do not fit"), std::string::npos);
}

class DepthResponseCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    folder_ = testing_support::temp_dir("depth-response-cache") /
              ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::filesystem::remove_all(folder_);
  }
  void TearDown() override { std::filesystem::remove_all(folder_); }
  // A response standing in for a measurement (its cost is the processing's, tested below), and
  // how often it was asked for.
  DepthResponse measure() {
    ++measured_;
    return DepthResponse(two_layers(), kShifts, {{-0.2, -0.1, 0, 0.1, 0.2}, {-0.24, -0.12, 0, 0.1, 0.18}});
  }
  std::filesystem::path folder_;
  int measured_ = 0;
};

TEST_F(DepthResponseCacheTest, AMissMeasuresAndKeepsItAHitReadsItBack) {
  DepthResponseDiskCache cache(folder_);
  const auto measure = [&] { return this->measure(); };
  const DepthResponse first = cache.response("key one", measure);
  EXPECT_EQ(cache.last_outcome(), CacheOutcome::missing) << cache.last_note();
  EXPECT_NE(
      cache.last_note().find("depth response measured and kept in the cache: " + cache.file_for("key one").string()),
      std::string::npos)
      << cache.last_note();
  const DepthResponse again = DepthResponseDiskCache(folder_).response("key one", measure);
  EXPECT_EQ(measured_, 1);
  EXPECT_EQ(again.measured_mm(), first.measured_mm());
  EXPECT_EQ(again.shifts_mm(), first.shifts_mm());
  EXPECT_EQ(again.field_grid(), first.field_grid());
  cache.response("key two", measure);  // another key, another file
  EXPECT_EQ(cache.last_outcome(), CacheOutcome::missing);
  EXPECT_EQ(measured_, 2);
  EXPECT_NE(cache.file_for("key one"), cache.file_for("key two"));
}

TEST_F(DepthResponseCacheTest, AStaleOrDamagedFileIsMeasuredAnewAndReplaced) {
  DepthResponseDiskCache cache(folder_);
  const auto measure = [&] { return this->measure(); };
  cache.response("key one", measure);
  // key one's file where key two's should be: the stored key tells them apart.
  std::filesystem::copy_file(cache.file_for("key one"), cache.file_for("key two"));
  cache.response("key two", measure);
  EXPECT_EQ(cache.last_outcome(), CacheOutcome::stale) << cache.last_note();
  EXPECT_NE(cache.last_note().find("replaced: stale"), std::string::npos) << cache.last_note();
  EXPECT_EQ(measured_, 2);
  cache.response("key two", measure);
  EXPECT_EQ(cache.last_outcome(), CacheOutcome::hit) << cache.last_note();
  // One byte of the response changed: the checksum refuses it.
  const std::filesystem::path file = cache.file_for("key one");
  std::string bytes;
  {
    std::ifstream in(file, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  bytes[bytes.size() - 3] ^= 0x10;
  std::ofstream(file, std::ios::binary | std::ios::trunc) << bytes;
  cache.response("key one", measure);
  EXPECT_EQ(cache.last_outcome(), CacheOutcome::corrupt) << cache.last_note();
  EXPECT_NE(cache.last_note().find("checksum"), std::string::npos) << cache.last_note();
  EXPECT_EQ(measured_, 3);
  cache.response("key one", measure);
  EXPECT_EQ(cache.last_outcome(), CacheOutcome::hit) << cache.last_note();
  EXPECT_EQ(measured_, 3);
}

TEST_F(DepthResponseCacheTest, AFolderItCannotWriteIsSaidAndTheResponseStillMeasured) {
  std::filesystem::create_directories(folder_.parent_path());
  std::ofstream(folder_) << "a file where the folder should be";
  DepthResponseDiskCache cache(folder_);
  const DepthResponse r = cache.response("key", [&] { return this->measure(); });
  EXPECT_EQ(cache.last_outcome(), CacheOutcome::unwritable);
  EXPECT_NE(cache.last_note().find("depth response measured, not kept in the cache ("), std::string::npos)
      << cache.last_note();
  EXPECT_EQ(r.shifts_mm(), kShifts);
  std::filesystem::remove(folder_);
}

// process.yaml's settings on the small camera with fewer passes and iterations (a unit test's
// time); the box on one side of the focal plane, as process.yaml's.
const std::string kSpec = std::string("dt_s: 0.0001") + testing_support::kShallowSmallBox +
                          "reconstruction: {iterations: 8, mu: 1, acceleration: nesterov";

ProcessSettings parse(const std::string& reconstruction_keys) {
  return process_settings_from(YamlMap(load_yaml_text(kSpec + reconstruction_keys + "}\n", "run.yaml"), "run.yaml"));
}

TEST(DepthResponse, TheSettingIsOffByDefaultAndRefusedOutsideZeroToFive) {
  EXPECT_EQ(parse("").depth_response_ppm, 0.0);
  EXPECT_EQ(parse(", depth_response_ppm: 0.5").depth_response_ppm, 0.5);
  for (const std::string bad : {"-0.1", "5.5", "nan", "many"})
    EXPECT_NE(error_of([&] { parse(", depth_response_ppm: " + bad); }).find("depth_response_ppm"), std::string::npos)
        << bad;
}

// Every setting goes into the key but dt (displacements do not depend on it), and so does the
// executable's build ID.
TEST(DepthResponse, ItsKeyTakesEveryProcessingSettingButDt) {
  const ProcessSettings base = parse("");
  const std::string key = settings_key(base);
  const auto changed = [&](auto&& change) {
    ProcessSettings s = base;
    change(s);
    return settings_key(s) != key;
  };
  EXPECT_EQ(settings_key(parse("")), key);
  EXPECT_FALSE(changed([](ProcessSettings& s) { s.correlation.dt_s *= 2; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.grid.origin_mm[2] += 0.125; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.depth_guard_mm = 2; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.depth_response_ppm = 0.25; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.mart.iterations += 1; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.mart.region = recon::RegionMm{}; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.mart.prune_depth_reach += 1; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.mart.prune_local_threshold = 0.05; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.mart.mlos_power = 3; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.correlation.passes.back().depth_margin += 1; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.correlation.passes.pop_back(); }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.correlation.median.radius += 1; }));
  EXPECT_TRUE(changed([](ProcessSettings& s) { s.correlation.whitened_peak_sigma_voxel[2] += 1; }));
  const optics::CameraModel camera = testing_support::small_camera();
  const std::string response_key = depth_response_key("operator", camera, base);
  ASSERT_FALSE(executable_build_id().empty()) << "the tests are linked with a build ID (the toolchain's default)";
  EXPECT_NE(response_key.find(executable_build_id()), std::string::npos);
  EXPECT_NE(response_key.find(key), std::string::npos);
  EXPECT_NE(depth_response_key("another operator", camera, base), response_key);
}

// A shear the response was not measured on (u, v / 2 and w grow along y, -2 to +2 voxels over the box)
// through a processor that measured it: most of w's shortfall goes, u and v stay the same bits. The
// processor keeps the response in its disk cache, and one built later reads it back from there.
TEST(DepthResponse, TakesMartsShortfallOutOfAShearsDepthComponent) {
  const optics::CameraModel camera = testing_support::small_camera();
  const calib::LoadedCalibration calibration = calib::nominal_calibration(camera);
  const double ppm = 0.5;
  const std::filesystem::path folder = testing_support::temp_dir("depth-response-shear");
  std::filesystem::remove_all(folder);
  std::vector<double> fractions;  // the set-up's progress: within and after each simulated pair
  const auto progress = [&](double f) { fractions.push_back(f); };
  const ProcessSettings settings = parse(", depth_response_ppm: " + std::to_string(ppm));
  OperatorCache operators(1, folder);
  ProcessorSetup setup;
  setup.operators = &operators;
  setup.progress = progress;
  const PairProcessor processor(camera, calibration, settings, setup);
  ASSERT_NE(processor.depth_response(), nullptr);
  // 25 vectors per layer here: four particle sets for each of the four shifts, each processed as it
  // is and with its particles scattered sideways: 32 pairs, each reported after its end (at k / 32)
  // and within it after every MART iteration and correlation pass.
  for (int k = 1; k <= 32; ++k)
    EXPECT_NE(
        std::find_if(fractions.begin(), fractions.end(), [&](double f) { return std::abs(f - k / 32.0) < 1e-12; }),
        fractions.end())
        << k << " / 32";
  EXPECT_GT(fractions.size(), 32u * 10);
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_DOUBLE_EQ(fractions.back(), 1.0);
  std::cout << "measured: " << processor.depth_response()->summary() << "\n";
  EXPECT_NE(processor.setup_note().find("depth response over z"), std::string::npos);
  EXPECT_NE(processor.setup_note().find("depth response measured and kept in the cache"), std::string::npos)
      << processor.setup_note();
  EXPECT_TRUE(processor.setup_on_disk());

  const double voxel = 0.125;
  const double rate = 2 * voxel / 2.0;                            // +-2 voxels at the box's y faces
  const sim::LinearShear flow({rate, 0.5 * rate, rate}, 1, 0.0);  // v too: every sub-voxel shift sideways
  const sim::Box box{{-3, -3, -2}, {3, 3, 6}};
  const std::vector<sim::Point3> a = sim::random_particles(box, sim::particle_count_from_ppm(camera, box, ppm), 4242);
  const std::vector<sim::Point3> b = sim::displace(a, flow);
  sim::RenderOptions ro;
  ro.rays_per_particle = 5000;
  const ImageU16 frame_a = sim::render(camera, calibration.lenses, a, ro, 31).image;
  const ImageU16 frame_b = sim::render(camera, calibration.lenses, b, ro, 32).image;

  const PairResult plain = processor.process_uncorrected(frame_a, frame_b);
  const PairResult corrected = processor.process(frame_a, frame_b);
  const sim::FieldErrors before = sim::field_errors(plain.correlation.field, flow, voxel, 3);
  const sim::FieldErrors after = sim::field_errors(corrected.correlation.field, flow, voxel, 3);
  std::cout << "measured: w's gain " << before.gain[2] << " -> " << after.gain[2] << ", RMS w " << before.rms[2]
            << " -> " << after.rms[2] << " voxels, bias w " << before.bias[2] << " -> " << after.bias[2] << ", "
            << after.compared << " vectors\n";
  EXPECT_EQ(corrected.correlation.field.dx_mm, plain.correlation.field.dx_mm);
  EXPECT_EQ(corrected.correlation.field.dy_mm, plain.correlation.field.dy_mm);
  EXPECT_EQ(corrected.correlation.field.valid, plain.correlation.field.valid);
  // Bounds from measurement (the values: docs/accuracy.md, this test's row). The gain stays below 1:
  // the shear keeps a shortfall the uniform shifts do not show; its RMS, bias included, stays.
  EXPECT_LT(before.gain[2], 0.8);
  EXPECT_GT(after.gain[2], 0.83);
  EXPECT_LT(after.gain[2], 1.05);
  EXPECT_LT(after.rms[2], 1.05 * before.rms[2]);
  // The widening the response measured takes sigma towards the error (w's bias, which no sigma of
  // random error sees, is in the error).
  const sim::UncertaintyCheck sigma_before = sim::uncertainty_check(plain.correlation.field, flow, voxel, 3, 0);
  const sim::UncertaintyCheck sigma_after = sim::uncertainty_check(corrected.correlation.field, flow, voxel, 3, 0);
  for (std::size_t a = 0; a < 3; ++a)
    std::cout << "measured: "
              << "uvw"[a] << " sigma / error " << sigma_before.rms_sigma[a] / sigma_before.rms_error[a] << " -> "
              << sigma_after.rms_sigma[a] / sigma_after.rms_error[a] << ", within 1 / 2 sigma "
              << sigma_before.within_1[a] << " / " << sigma_before.within_2[a] << " -> " << sigma_after.within_1[a]
              << " / " << sigma_after.within_2[a] << "\n";
  ASSERT_EQ(processor.depth_response()->sigma_widening().size(), std::size_t(plain.correlation.field.grid.shape[2]));
  for (const SigmaWidening& widening : processor.depth_response()->sigma_widening())
    EXPECT_GT(widening.unseen_w_mm, 0.0);  // MART's depth error is never all in the correlation's sigma
  // Bounds from measurement (the values: docs/accuracy.md): on this shallow box beside the focal
  // plane the correlation's own sigma already about matches w's error, and the calibration's error
  // added to it makes w's sigma wider than the error: an over-estimate, never narrower.
  const auto ratio = [](const sim::UncertaintyCheck& c, std::size_t a) { return c.rms_sigma[a] / c.rms_error[a]; };
  EXPECT_GT(ratio(sigma_after, 2), ratio(sigma_before, 2) + 0.5);
  EXPECT_LT(ratio(sigma_after, 2), 2.1);
  EXPECT_GT(sigma_after.within_2[2], 0.95);
  for (std::size_t a = 0; a < 2; ++a)  // lateral: never narrowed
    EXPECT_GE(sigma_after.rms_sigma[a], sigma_before.rms_sigma[a]);
  // v, whose own sigma falls short here, is scaled towards its error (bounds from measurement).
  EXPECT_GT(ratio(sigma_after, 1), ratio(sigma_before, 1) + 0.1);
  EXPECT_LT(ratio(sigma_after, 1), 1.3);

  OperatorCache later_operators(1, folder);
  const std::size_t reported = fractions.size();
  setup.operators = &later_operators;
  const PairProcessor later(camera, calibration, settings, setup);
  EXPECT_EQ(fractions.size(), reported) << "measured again";
  EXPECT_NE(later.setup_note().find("depth response from the cache"), std::string::npos) << later.setup_note();
  EXPECT_TRUE(later.setup_on_disk());
  EXPECT_EQ(later.process(frame_a, frame_b).correlation.field.dz_mm, corrected.correlation.field.dz_mm);
  std::filesystem::remove_all(folder);
}

// Tracing a simulated frame takes seconds at the paper's scale: the measurement's progress is
// told as it goes (about every 1 % of the particles, on the calling thread), so that a caller can
// end it there, not only after each MART iteration and correlation pass.
TEST(DepthResponse, ItsProgressIsToldWhileItsFramesAreTracedAndCanEndItThere) {
  const optics::CameraModel camera = testing_support::small_camera();
  const calib::LoadedCalibration calibration = calib::nominal_calibration(camera);
  ProcessSettings settings = parse("");
  settings.mart.iterations = 2;
  const PairProcessor processor(camera, calibration, settings);
  // One thread: every report of the tracer is on the calling thread, so their count is known.
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  std::vector<double> fractions;
  const auto stop_after_first_pair = [&](double f) {
    fractions.push_back(f);
    if (f > 0) throw Cancelled("stopped");
  };
  EXPECT_THROW(measure_depth_response(processor, camera, calibration.lenses, 0.2, stop_after_first_pair), Cancelled);
  // The first pair (fraction 0 throughout): its two frames' tracing reports about 100 times each;
  // its MART iterations and correlation passes alone, fewer than 20 times.
  const auto first_pair = std::size_t(std::count(fractions.begin(), fractions.end(), 0.0));
  EXPECT_GE(first_pair, 200u);
  EXPECT_EQ(fractions.size(), first_pair + 1);  // the stop at the next report: the next frame's tracing
}

// A deferred depth response (plenopivd's quality lane) is taken by the first pair, with that pair's
// progress (stage "depth response"); a pair whose progress gives up leaves it to the next and keeps
// nothing. The response it measures is kept in its folder, and its fields are the bits of a
// processor built later that reads the response from there when it is built (measured once: the
// deferred and the constructor's response are one function of the same processor, and the shear
// test above holds a kept response to the bits of the measured one).
TEST(DepthResponse, ADeferredResponseIsTakenByTheFirstPairThatFinishes) {
  const optics::CameraModel camera = testing_support::small_camera();
  const calib::LoadedCalibration calibration = calib::nominal_calibration(camera);
  // A test's time (most of it the simulator's frames): two iterations, 0.2 particles per microlens.
  ProcessSettings settings = parse(", depth_response_ppm: 0.2");
  settings.mart.iterations = 2;
  const std::filesystem::path folder = testing_support::temp_dir("depth-response-deferred");
  std::filesystem::remove_all(folder);
  // Every entry of the folder: a response, or a temporary one left behind (".depth-response-...").
  const auto kept = [&] { return testing_support::entries_named(folder, ""); };
  ProcessorSetup later_on;
  later_on.response_folder = folder;
  later_on.defer_depth_response = true;
  const PairProcessor deferred(camera, calibration, settings, later_on);
  EXPECT_EQ(deferred.depth_response(), nullptr);
  EXPECT_TRUE(deferred.depth_response_note().empty());
  EXPECT_NE(deferred.setup_note().find("depth response deferred to the first pair"), std::string::npos)
      << deferred.setup_note();

  const sim::UniformFlow flow({0.05, -0.03, 0.125});
  const sim::Box box{{-3, -3, -2}, {3, 3, 6}};
  const std::vector<sim::Point3> a = sim::random_particles(box, sim::particle_count_from_ppm(camera, box, 0.5), 77);
  sim::RenderOptions ro;
  ro.rays_per_particle = 2000;
  const ImageU16 frame_a = sim::render(camera, calibration.lenses, a, ro, 1).image;
  const ImageU16 frame_b = sim::render(camera, calibration.lenses, sim::displace(a, flow), ro, 2).image;

  int reports = 0;
  PairOptions stopped;
  stopped.progress = [&](const std::string& stage, double) {
    if (stage == "depth response" && ++reports == 3) throw Cancelled("stopped");
  };
  EXPECT_THROW(deferred.process(frame_a, frame_b, stopped), Cancelled);
  EXPECT_EQ(deferred.depth_response(), nullptr);
  EXPECT_EQ(kept(), 0u) << "a response given up was kept";

  std::vector<std::string> stages;
  PairOptions go;
  go.progress = [&](const std::string& stage, double) { stages.push_back(stage); };
  const PairResult first = deferred.process(frame_a, frame_b, go);
  ASSERT_NE(deferred.depth_response(), nullptr);
  EXPECT_NE(deferred.depth_response_note().find("depth response over z"), std::string::npos)
      << deferred.depth_response_note();
  ASSERT_FALSE(stages.empty());
  EXPECT_EQ(stages.front(), "depth response");
  EXPECT_NE(stages.back(), "depth response");
  EXPECT_NE(deferred.depth_response_note().find("depth response measured and kept in the cache"), std::string::npos)
      << deferred.depth_response_note();
  EXPECT_EQ(kept(), 1u);
  ProcessorSetup from_folder;
  from_folder.response_folder = folder;
  const PairProcessor built(camera, calibration, settings, from_folder);
  ASSERT_NE(built.depth_response(), nullptr);
  EXPECT_NE(built.setup_note().find("depth response from the cache"), std::string::npos) << built.setup_note();
  const PairResult reference = built.process(frame_a, frame_b);
  EXPECT_EQ(first.correlation.field.dz_mm, reference.correlation.field.dz_mm);
  // NaN where no sigma: compared as bits.
  const std::vector<float>& sigma = first.correlation.field.sigma_dz_mm;
  const std::vector<float>& reference_sigma = reference.correlation.field.sigma_dz_mm;
  ASSERT_EQ(sigma.size(), reference_sigma.size());
  EXPECT_EQ(std::memcmp(sigma.data(), reference_sigma.data(), sigma.size() * sizeof(float)), 0);
  stages.clear();
  deferred.process(frame_a, frame_b, go);  // taken once
  EXPECT_EQ(std::count(stages.begin(), stages.end(), "depth response"), 0);
  std::filesystem::remove_all(folder);
}

// A deferred response the settings cannot have (a layer that barely follows the shifts: one pass
// of 2 mm windows without a depth margin, two MART iterations) fails the first pair with the
// response's InputError, and every pair after it with the same error, without measuring again.
// A layer does not follow the first (outermost) shift: the measurement stops there.
TEST(DepthResponse, ADeferredResponseThatIsRefusedFailsEveryPairWithoutMeasuringAgain) {
  const optics::CameraModel camera = testing_support::small_camera();
  const calib::LoadedCalibration calibration = calib::nominal_calibration(camera);
  ProcessSettings settings = parse(", depth_response_ppm: 0.5");
  settings.mart.iterations = 2;
  settings.correlation.passes = {piv::PassSettings{{16, 16, 8}, 50, 0}};
  settings.correlation.depth_prefilter = 0;
  settings.correlation.final_smoothing = 0;
  ProcessorSetup later_on;
  later_on.defer_depth_response = true;
  const PairProcessor deferred(camera, calibration, settings, later_on);
  const ImageU16 dark(camera.sensor().width_px, camera.sensor().height_px);
  std::size_t reports = 0;
  PairOptions options;
  options.progress = [&](const std::string& stage, double) { reports += stage == "depth response"; };
  const std::string first = error_of([&] { deferred.process(dark, dark, options); });
  EXPECT_NE(first.find("depth response: the vectors at z = "), std::string::npos) << first;
  EXPECT_NE(first.find("(true -> measured mm: -0.25 -> "), std::string::npos) << first;
  EXPECT_NE(first.find(", -0.125 -> not measured, 0 -> 0, 0.125 -> not measured, 0.25 -> not measured)"),
            std::string::npos)
      << first;
  std::cout << "measured: " << first << "\n";
  EXPECT_GT(reports, 0u);
  const std::size_t measured = reports;
  EXPECT_EQ(error_of([&] { deferred.process(dark, dark, options); }), first);
  EXPECT_EQ(reports, measured) << "measured again";
  EXPECT_EQ(deferred.depth_response(), nullptr);
}

}  // namespace
}  // namespace plenopiv::process
