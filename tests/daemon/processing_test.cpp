// The live processing stage on ray-traced pairs (core/sim): a known uniform displacement comes back.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>

#include "core/base/errors.hpp"
#include "core/optics/camera_file.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "daemon/processing.hpp"
#include "tests/support/captured_log.hpp"
#include "tests/support/shallow_spec.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::daemon {
namespace {

const std::string kConfig =
    "dt_s: 0.001\n"
    "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-1, 1], voxel_mm: 0.125}\n"
    // Live settings on cubes (MLOS start, dark cutoff 0.9: MART's defaults).
    "reconstruction: {iterations: 3, mu: 1}\n"
    // Two passes: the predictor of the first removes the loss-of-pairs bias of a single pass.
    "correlation: {passes: [{window: 16, overlap_percent: 50}, {window: 8, overlap_percent: 50}],\n"
    "              intensity_threshold_of_mean: 4}\n";

TEST(Processing, UniformDisplacementOfARayTracedPairComesBack) {
  const optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  const sim::Box box{{-1, -1, -1}, {1, 1, 1}};
  const std::vector<sim::Point3> a = sim::random_particles(box, 30, 7);
  std::vector<sim::Point3> b = a;
  const double shift_mm = 0.25;  // 2 voxels along x
  for (auto& p : b) p[0] += shift_mm;
  sim::RenderOptions options;
  options.rays_per_particle = 100000;
  // A camera's pedestal (no read noise: the frames are the ray counts plus 30), which the
  // processing takes off before MART (reconstruction.black_level).
  options.sensor.dark_offset_dn = 30;
  drivers::FramePair pair;
  pair.a.image = sim::render(camera, lenses, a, options, 1).image;
  pair.b.image = sim::render(camera, lenses, b, options, 2).image;

  const RunConfig config = parse_run_config(kConfig, "run.yaml");
  const auto t0 = std::chrono::steady_clock::now();
  const ProcessFn process = plenoptic_processing(camera)(config, RunCalibration{}, process::Tier::full, {});
  const CancelFlag go{false};
  const ProcessedPair out = process(pair, PairSteps(go));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  const VectorField& f = out.vectors;
  EXPECT_DOUBLE_EQ(f.dt_s, 1e-3);
  double sum = 0, sum_y = 0;
  std::size_t valid = 0;
  for (std::size_t i = 0; i < f.valid.size(); ++i) {
    if (!f.valid[i]) continue;
    ++valid;
    sum += f.dx_mm[i];
    sum_y += f.dy_mm[i];
  }
  ASSERT_GT(valid, 0u);
  const double mean_dx = sum / double(valid), mean_dy = sum_y / double(valid);
  double sum_z = 0;
  for (std::size_t i = 0; i < f.valid.size(); ++i) sum_z += f.valid[i] ? f.dz_mm[i] : 0.0;
  std::printf(
      "processing: %zu of %zu vectors valid, mean dx %.9f mm (truth %.4f), mean dy %.9f mm, "
      "mean dz %.9f mm, %.1f s\n",
      valid, f.valid.size(), mean_dx, shift_mm, mean_dy, sum_z / double(valid), seconds);
  // Every vector valid and the mean the simulator's shift.
  EXPECT_EQ(valid, f.valid.size());
  EXPECT_NEAR(mean_dx, shift_mm, 0.02) << "measured 0.2505 mm";
  EXPECT_NEAR(mean_dy, 0.0, 0.01);
  // Every measured vector has its uncertainty (the live path's correlation estimates it).
  ASSERT_EQ(f.sigma_dz_mm.size(), f.valid.size());
  std::size_t with_sigma = 0;
  for (std::size_t i = 0; i < f.valid.size(); ++i)
    with_sigma += f.valid[i] && f.sigma_dx_mm[i] > 0 && f.sigma_dy_mm[i] > 0 && f.sigma_dz_mm[i] > 0;
  EXPECT_GT(with_sigma, valid / 2) << "of " << valid;
  // ... and says what it holds: the final pass's correlation statistics, a floor on MART's volumes.
  EXPECT_EQ(f.sigma_method.rfind("correlation statistics of the final pass (Wieneke 2015)", 0), 0u) << f.sigma_method;
  EXPECT_NE(f.sigma_method.find("a floor"), std::string::npos) << f.sigma_method;

  // What MART skipped, for the status and the log: 3 iterations per frame, each updating the live
  // voxels of a box mostly dark at 30 particles, the shares consistent with those counts.
  ASSERT_TRUE(out.work);
  const ReconstructionWork& w = *out.work;
  ASSERT_EQ(w.live_a.size(), 3u);
  ASSERT_EQ(w.live_b.size(), 3u);
  std::size_t updates = 0;
  for (const auto* live : {&w.live_a, &w.live_b}) {
    for (const std::size_t n : *live) {
      EXPECT_GT(n, 0u);
      EXPECT_LT(n, w.voxels);
      updates += n;
    }
  }
  EXPECT_NEAR(w.updates_skipped, 1.0 - double(updates) / (6.0 * double(w.voxels)), 1e-12);
  std::printf("processing: voxel updates skipped %.4f of %zu voxels x 6 iterations\n", w.updates_skipped, w.voxels);
  EXPECT_GT(w.updates_skipped, 0.5) << "measured " << w.updates_skipped;
  EXPECT_EQ(w.work_pruned, 0.0);  // no exact zeros in ray-traced frames; no threshold
  EXPECT_EQ(w.black_level_a, 30.0);
  EXPECT_EQ(w.black_level_b, 30.0);
  for (const double level :
       {w.black_level_a_lowest, w.black_level_a_highest, w.black_level_b_lowest, w.black_level_b_highest})
    EXPECT_EQ(level, 30.0);  // one offset over the sensor: every tile reads it

  // A stopping run: the same pair gives up at the first MART iteration's check.
  const CancelFlag stop{true};
  EXPECT_THROW(process(pair, PairSteps(stop)), Cancelled);
}

TEST(Processing, BadSettingsAndWrongImagesAreNamed) {
  const optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const ProcessFactory factory = plenoptic_processing(camera);
  const std::string bad =
      "dt_s: 0.001\nvolume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-1, 1], voxel_mm: 0.125}\n"
      "reconstruction: {iteratons: 3}\n";
  try {
    parse_run_config(bad, "run.yaml");
    FAIL() << "a misspelt reconstruction key was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("reconstruction.iteratons: unknown key"), std::string::npos) << e.what();
  }
  // A volume whose pairs in flight would not fit this machine's memory: refused with the estimate
  // before any table is built (2^29 voxels is what run.yaml itself allows).
  try {
    factory(
        parse_run_config("dt_s: 0.001\nvolume: {x_mm: [-100, 100], y_mm: [-100, 100], z_mm: [-5, 5], voxel_mm: 0.125}\n"
                         "max_pairs_in_flight: 4\n",
                         "run.yaml"),
        RunCalibration{}, process::Tier::full, {});
    FAIL() << "a 1600 x 1600 x 96 voxel volume with 4 pairs in flight was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("processing 4 pair(s) at once on a 1600 x 1600 x"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("GB of memory"), std::string::npos) << e.what();
  }
  const ProcessFn process = factory(parse_run_config(kConfig, "run.yaml"), RunCalibration{}, process::Tier::full, {});
  drivers::FramePair small;
  small.a.image = ImageU16(64, 48);
  small.b.image = ImageU16(64, 48);
  const CancelFlag go{false};
  EXPECT_THROW(process(small, PairSteps(go)), InputError);  // not the camera's sensor size
}

// The factory keeps the operators it built (process::OperatorCache): a second run on the same
// camera, calibration and volume builds no weight tables, a run on another volume does; each run
// says which in its log line.
TEST(Processing, ARunOnAnEarlierRunsGeometryBuildsNoTables) {
  const optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const testing_support::CapturedLog log(8);
  const ProcessFactory factory = plenoptic_processing(camera);
  const RunConfig config = parse_run_config(kConfig, "run.yaml");
  std::string other = kConfig;
  other.replace(other.find("x_mm: [-1, 1]"), 13, "x_mm: [-1.25, 1.25]");
  factory(config, RunCalibration{}, process::Tier::full, {});
  factory(config, RunCalibration{}, process::Tier::full, {});
  factory(parse_run_config(other, "run.yaml"), RunCalibration{}, process::Tier::full, {});
  // Each run logs its operator line, then the line of the buffers it reserved.
  std::vector<std::string> lines, reserved;
  for (const std::string& line : log.lines())
    (line.find("reserved") == std::string::npos ? lines : reserved).push_back(line);
  EXPECT_EQ(reserved.size(), 3u);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_NE(lines[0].find("operator built"), std::string::npos) << lines[0];
  EXPECT_NE(lines[1].find("operator kept in memory"), std::string::npos) << lines[1];
  EXPECT_NE(lines[2].find("operator built"), std::string::npos) << lines[2];
}

// A run whose settings ask for a depth response measures it while Armed, saying how far it is
// through the factory's progress, and keeps it in the factory's folder, where a later daemon's
// factory reads it back. A stop during the measurement (the run's progress throws) ends it there
// and keeps nothing.
TEST(Processing, ADepthResponseIsMeasuredWithProgressKeptAndEndedByAStop) {
  const optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const std::filesystem::path folder = testing_support::temp_dir("daemon-depth-response");
  std::filesystem::remove_all(folder);
  // The small camera's shallow box, where MART follows depth shifts.
  const RunConfig config = parse_run_config(std::string("dt_s: 0.0001") + testing_support::kShallowSmallBox +
                                                "reconstruction: {iterations: 2, mu: 1, acceleration: nesterov, "
                                                "depth_response_ppm: 0.2}\n",
                                            "run.yaml");
  const auto files = [&] { return testing_support::entries_named(folder, "depth-response-"); };
  std::vector<std::string> steps;
  std::vector<double> fractions;
  const SetupProgress stopped_at_third = [&](const std::string& step, double fraction) {
    steps.push_back(step);
    fractions.push_back(fraction);
    if (fractions.size() == 3) throw Cancelled("run stopped");
  };
  EXPECT_THROW(plenoptic_processing(camera, folder)(config, RunCalibration{}, process::Tier::full, stopped_at_third),
               Cancelled);
  EXPECT_EQ(fractions.size(), 3u);
  EXPECT_EQ(files(), 0u) << "a response given up was kept";

  steps.clear();
  fractions.clear();
  const SetupProgress record = [&](const std::string& step, double fraction) {
    steps.push_back(step);
    fractions.push_back(fraction);
  };
  {
    const testing_support::CapturedLog log(8);
    plenoptic_processing(camera, folder)(config, RunCalibration{}, process::Tier::full, record);
    ASSERT_GT(fractions.size(), 2u);
    EXPECT_EQ(fractions.front(), 0.0);  // said before the weight tables
    EXPECT_DOUBLE_EQ(fractions.back(), 1.0);
    EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
    for (const std::string& step : steps) EXPECT_EQ(step, "depth response of the full tier");
    const std::vector<std::string> lines = log.lines();
    ASSERT_FALSE(lines.empty());
    EXPECT_NE(lines.front().find("depth response measured and kept in the cache: " + folder.string()),
              std::string::npos)
        << lines.front();
    EXPECT_NE(lines.front().find("depth response over z"), std::string::npos) << lines.front();
    EXPECT_EQ(files(), 1u);
  }
  fractions.clear();
  {
    const testing_support::CapturedLog log(8);
    plenoptic_processing(camera, folder)(config, RunCalibration{}, process::Tier::full, record);
    EXPECT_EQ(fractions, std::vector<double>{0.0});  // nothing measured
    const std::vector<std::string> lines = log.lines();
    ASSERT_FALSE(lines.empty());
    EXPECT_NE(lines.front().find("depth response from the cache: " + folder.string()), std::string::npos)
        << lines.front();
  }
  std::filesystem::remove_all(folder);
}

// The quality lane's tier measures its depth response with its first pair, not while Armed, and
// says how far it is in the lane's status as it goes (PairSteps::say); later pairs say nothing.
TEST(Processing, AQualityLanesDepthResponseIsMeasuredByItsFirstPairAndSaidAsItGoes) {
  const optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const std::filesystem::path folder = testing_support::temp_dir("daemon-deferred-depth-response");
  std::filesystem::remove_all(folder);
  const RunConfig config = parse_run_config(std::string("dt_s: 0.0001") + testing_support::kShallowSmallBox +
                                                "reconstruction: {iterations: 2, mu: 1, acceleration: nesterov, "
                                                "depth_response_ppm: 0.2}\n"
                                                "live: {reconstruction: {depth_response_ppm: 0}}\n",
                                            "run.yaml");
  ASSERT_TRUE(config.quality.on());
  ASSERT_EQ(config.live_lane_tier(), process::Tier::live);
  const auto files = [&] { return testing_support::entries_named(folder, "depth-response-"); };
  std::vector<double> setup_fractions;
  const ProcessFn process = plenoptic_processing(camera, folder)(
      config, RunCalibration{}, process::Tier::full,
      [&](const std::string&, double fraction) { setup_fractions.push_back(fraction); });
  EXPECT_TRUE(setup_fractions.empty()) << "the quality lane's response was measured while Armed";
  EXPECT_EQ(files(), 0u);

  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  const std::vector<sim::Point3> a = sim::random_particles(sim::Box{{-2, -2, 0}, {2, 2, 4}}, 60, 11);
  std::vector<sim::Point3> b = a;
  for (auto& p : b) p[2] += 0.25;
  sim::RenderOptions options;
  options.rays_per_particle = 20000;
  drivers::FramePair pair;
  pair.a.image = sim::render(camera, lenses, a, options, 1).image;
  pair.b.image = sim::render(camera, lenses, b, options, 2).image;
  const CancelFlag go{false};
  {
    StageActivity activity;
    const ProcessedPair out = process(pair, PairSteps(go, nullptr, &activity));
    EXPECT_GT(out.vectors.valid.size(), 0u);
    // The pipeline clears it when the pair ends; here the last thing said is left.
    const std::string said = activity.text();
    EXPECT_EQ(said.rfind("depth response of the full tier, 100 % measured, ", 0), 0u) << said;
    EXPECT_NE(said.find(" s so far (its first pair; kept for later runs)"), std::string::npos) << said;
    EXPECT_EQ(files(), 1u);
  }
  {
    StageActivity activity;
    process(pair, PairSteps(go, nullptr, &activity));
    EXPECT_EQ(activity.text(), "") << "a later pair said the response again";
  }
  std::filesystem::remove_all(folder);
}

// The quality lane's status while its first pair measures the response: the tier, how far and how
// long (measured_so_far, pipeline_test), and that it is the lane's first pair.
TEST(Processing, ADepthResponsesActivitySaysItsTierHowFarAndHowLong) {
  EXPECT_EQ(depth_response_activity(process::Tier::full, 0.25, 60),
            "depth response of the full tier, 25 % measured, 60 s so far, about 3 min left (its first pair; kept "
            "for later runs)");
  EXPECT_EQ(depth_response_activity(process::Tier::live, 1.0, 30),
            "depth response of the live tier, 100 % measured, 30 s so far (its first pair; kept for later runs)");
}

}  // namespace
}  // namespace plenopiv::daemon
