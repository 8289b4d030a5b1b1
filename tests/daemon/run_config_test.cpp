// run.yaml: the shipped default parses; wrong keys and values are errors that name the key.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "core/base/errors.hpp"
#include "core/process/process.hpp"
#include "daemon/run_config.hpp"

namespace plenopiv::daemon {
namespace {

// A run config's processing keys are core/process's, so they need what process.yaml needs: dt_s, and
// windows that fit the volume.
const std::string kVolume =
    "dt_s: 0.0001\nvolume: {x_mm: [-1, 1], y_mm: [-2, 2], z_mm: [0, 2], voxel_mm: 0.5}\n"
    "correlation: {passes: [{window: 4, overlap_percent: 50}]}\n";

std::string error_of(const std::string& text) {
  try {
    parse_run_config(text, "run.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(RunConfig, ShippedDefaultParses) {
  std::ifstream in(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/run.yaml");
  std::stringstream text;
  text << in.rdbuf();
  const RunConfig c = parse_run_config(text.str(), "run.yaml");
  EXPECT_EQ(c.pair_count, 20u);
  EXPECT_DOUBLE_EQ(c.rate_hz, 2.0);
  EXPECT_DOUBLE_EQ(c.camera_outage_s, 30.0);
  EXPECT_DOUBLE_EQ(c.dt_s, 1e-4);
  EXPECT_TRUE(c.camera_uri.empty());  // the daemon's default camera
  EXPECT_EQ(c.spec.full.mart.iterations, 4);
  const process::ProcessSettings s =
      process::process_settings_from(YamlMap(load_yaml_text(c.process_yaml(), "process.yaml"), "process.yaml"));
  // [-2, 2] mm at 0.125 mm across and 0.25 mm deep: the box's faces
  EXPECT_EQ(s.grid.shape, (std::array<int, 3>{32, 32, 16}));
  ASSERT_EQ(s.correlation.passes.size(), 2u);
  EXPECT_EQ(s.correlation.passes[0].depth_margin, 2);  // depth motion recovered twice over (benchmarks.md)
  EXPECT_EQ(s.correlation.passes[1].window, (std::array<int, 3>{8, 8, 4}));
  EXPECT_EQ(s.correlation.depth_prefilter, 1);
  EXPECT_EQ(s.correlation.final_smoothing, 1);
  EXPECT_DOUBLE_EQ(s.correlation.spectral_whitening, 0.5);  // w truer on the demo's seeding (docs/lab/)
  EXPECT_FALSE(c.publish_volumes);
  EXPECT_EQ(c.text, text.str());
}

// The paper-scale live config gives core/process the paper's box and the full settings of
// docs/benchmarks.md's "Paper scale: time against error" for the quality lane, and the live tier
// chosen in its "Live tier" for the live lane.
TEST(RunConfig, ShippedPaperScaleConfigParses) {
  std::ifstream in(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/run-paper.yaml");
  std::stringstream text;
  text << in.rdbuf();
  const RunConfig c = parse_run_config(text.str(), "run-paper.yaml");
  EXPECT_EQ(c.max_pairs_in_flight, 1);
  const process::ProcessSettings s =
      process::process_settings_from(YamlMap(load_yaml_text(c.process_yaml(), "process.yaml"), "process.yaml"));
  EXPECT_EQ(s.grid.shape, (std::array<int, 3>{300, 200, 100}));  // the paper's box, voxels twice as deep
  EXPECT_EQ(s.grid.spacing_mm, (std::array<double, 3>{0.125, 0.125, 0.25}));
  EXPECT_EQ(s.mart.iterations, 8);
  EXPECT_DOUBLE_EQ(s.mart.mu, 1.0);
  EXPECT_TRUE(s.mart.accelerate);
  EXPECT_DOUBLE_EQ(s.mart.prune_threshold, 0.01);  // of each depth slice's peak ("Choosing settings")
  EXPECT_EQ(s.mart.prune_scope, recon::PruneScope::slice);
  EXPECT_DOUBLE_EQ(s.mart.prune_local_threshold, 0.05);  // of the neighbourhood's peak: halos, not faint particles
  EXPECT_DOUBLE_EQ(s.depth_response_ppm, 0.5);           // w through MART's depth response at the paper's seeding
  ASSERT_EQ(s.correlation.passes.size(), 5u);            // core/piv's default with a third 2 mm, 50 % pass
  EXPECT_EQ(s.correlation.passes[0].window, (std::array<int, 3>{32, 32, 16}));  // 4 mm cubes
  EXPECT_EQ(s.correlation.passes[1].depth_margin, 2);                           // 0.5 mm
  EXPECT_EQ(s.correlation.passes[4].window, (std::array<int, 3>{16, 16, 8}));   // 2 mm cubes
  EXPECT_DOUBLE_EQ(s.correlation.passes[4].overlap_percent, 75.0);
  EXPECT_DOUBLE_EQ(s.correlation.intensity_threshold_of_mean, 3.0);
  EXPECT_EQ(s.correlation.depth_prefilter, 1);  // four passes' smoothing at 0.125 mm
  EXPECT_EQ(s.correlation.final_smoothing, 1);
  EXPECT_EQ(s.correlation.early_interpolation, piv::Interpolation::cubic);  // the last pass keeps the sinc
  EXPECT_EQ(s.correlation.uncertainty_stride, 2);  // sigma every second node per axis, interpolated between
  EXPECT_EQ(s.pixel_binning, 1);

  ASSERT_TRUE(c.spec.live);
  const process::ProcessSettings& live = *c.spec.live;
  EXPECT_EQ(live.grid.shape, (std::array<int, 3>{100, 67, 33}));  // the same box in 0.375 x 0.75 mm voxels
  EXPECT_EQ(live.pixel_binning, 4);
  EXPECT_EQ(live.mart.iterations, 4);
  EXPECT_TRUE(live.mart.accelerate);
  EXPECT_EQ(live.mart.prune_scope, recon::PruneScope::slice);  // the live tier keeps the full settings'
  EXPECT_DOUBLE_EQ(live.mart.prune_threshold, 0.1);            // its own cut: ghosts of 4 coarse iterations
  EXPECT_DOUBLE_EQ(live.mart.prune_local_threshold, 0.0);      // and none against the neighbourhood's peak
  EXPECT_DOUBLE_EQ(live.depth_response_ppm, 0.0);              // its gain divided out would multiply its noise
  ASSERT_EQ(live.correlation.passes.size(), 2u);
  EXPECT_EQ(live.correlation.passes[1].window, (std::array<int, 3>{8, 8, 4}));  // 3 mm cubes
  EXPECT_EQ(live.correlation.depth_prefilter, 1);
  EXPECT_EQ(live.correlation.uncertainty_stride, 1);  // windows at 50 %: every vector's own
  EXPECT_EQ(c.quality.take, QualityLane::Take::newest);
}

// volume ranges are the box's faces, as in process.yaml: one meaning wherever the key is read.
TEST(RunConfig, VolumeRangesAreTheBoxFacesAsInProcessYaml) {
  const RunConfig c = parse_run_config(kVolume, "run.yaml");
  const Grid3 g = c.volume_grid();
  EXPECT_EQ(g.shape, (std::array<int, 3>{4, 8, 4}));
  EXPECT_EQ(g.origin_mm, (std::array<double, 3>{-0.75, -1.75, 0.25}));
  EXPECT_EQ(g.spacing_mm, (std::array<double, 3>{0.5, 0.5, 0.5}));
  EXPECT_EQ(c.pair_count, 0u);  // until stopped
  EXPECT_EQ(g, process::process_settings_from(YamlMap(load_yaml_text(kVolume, "process.yaml"), "process.yaml")).grid);
}

// A live section overrides the full settings key by key: the live lane's fast tier.
TEST(RunConfig, ALiveSectionIsTheFastTierOverridingTheFullSettings) {
  const RunConfig c = parse_run_config(
      "dt_s: 0.0001\nvolume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [0, 4], voxel_mm: 0.25}\n"
      "reconstruction: {iterations: 8, mu: 1}\ncorrelation: {passes: [{window: 8, overlap_percent: 50}]}\n"
      "live: {volume: {voxel_mm: 0.5}, reconstruction: {iterations: 2},\n"
      "       correlation: {passes: [{window: 4, overlap_percent: 0}]}}\n",
      "run.yaml");
  ASSERT_TRUE(c.spec.live);
  EXPECT_EQ(c.spec.full.grid.shape, (std::array<int, 3>{16, 16, 16}));
  EXPECT_EQ(c.spec.live->grid.shape, (std::array<int, 3>{8, 8, 8}));  // coarser voxels, the same box
  EXPECT_EQ(c.spec.full.mart.iterations, 8);
  EXPECT_EQ(c.spec.live->mart.iterations, 2);
  EXPECT_DOUBLE_EQ(c.spec.live->mart.mu, 1.0);  // not overridden: the full tier's
  EXPECT_DOUBLE_EQ(c.spec.live->correlation.passes[0].overlap_percent, 0.0);
  EXPECT_DOUBLE_EQ(c.spec.live->correlation.dt_s, 1e-4);
  EXPECT_FALSE(parse_run_config(kVolume, "run.yaml").spec.live);
  // A bad key in the live section is named as the live tier's.
  const std::string e = error_of(kVolume + "live: {reconstruction: {iterations: 0}}\n");
  EXPECT_NE(e.find("run.yaml (live tier): reconstruction.iterations: must be 1 to 10000"), std::string::npos) << e;
  EXPECT_NE(error_of(kVolume + "live: {dt_s: 0.1}\n").find("live.dt_s: unknown key"), std::string::npos)
      << error_of(kVolume + "live: {dt_s: 0.1}\n");
  // Deep voxels in the full settings and a live tier that sets voxel_mm alone: its depth is asked for.
  const std::string deep =
      "pairs: 1\nrate_hz: 1\ndt_s: 1e-4\nvolume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [-2, 2], "
      "voxel_mm: 0.25, voxel_z_mm: 0.5}\ncorrelation: {passes: [{window: 4, overlap_percent: 50}]}\n";
  const std::string e_deep = error_of(deep + "live: {volume: {voxel_mm: 0.5}}\n");
  EXPECT_NE(e_deep.find("live.volume.voxel_z_mm: missing"), std::string::npos) << e_deep;
  const RunConfig both = parse_run_config(deep + "live: {volume: {voxel_mm: 0.5, voxel_z_mm: 1}}\n", "run.yaml");
  ASSERT_TRUE(both.spec.live);
  EXPECT_EQ(both.spec.live->grid.shape, (std::array<int, 3>{8, 8, 4}));
  EXPECT_EQ(parse_run_config(deep, "run.yaml").spec.full.grid.shape, (std::array<int, 3>{16, 16, 8}));
}

TEST(RunConfig, UnknownKeyIsNamed) {
  const std::string e = error_of(kVolume + "pairz: 3\n");
  EXPECT_NE(e.find("run.yaml: pairz: unknown key"), std::string::npos) << e;
}

TEST(RunConfig, UnknownVolumeKeyIsNamedWithItsPath) {
  const std::string e = error_of("volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 1], voxel: 0.5}\n");
  EXPECT_NE(e.find("volume.voxel: unknown key"), std::string::npos) << e;
}

TEST(RunConfig, BadValuesAreNamed) {
  EXPECT_NE(error_of(kVolume + "pairs: -1\n").find("pairs: must be >= 0"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "rate_hz: 0\n").find("rate_hz"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "camera_outage_s: -1\n").find("camera_outage_s: must be in [0, 3600] s"),
            std::string::npos);
  EXPECT_NE(error_of(kVolume + "reconstruction: 3\n").find("reconstruction: expected a mapping"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "max_pairs_in_flight: 0\n").find("max_pairs_in_flight"), std::string::npos);
  EXPECT_NE(error_of("dt_s: 0.001\nvolume: {x_mm: [1, -1], y_mm: [-1, 1], z_mm: [0, 1], voxel_mm: 1}\n")
                .find("x extent needs min < max"),
            std::string::npos);
  EXPECT_NE(error_of("dt_s: 0.001\nvolume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 1]}\n").find("voxel_mm"),
            std::string::npos);
  EXPECT_NE(error_of("dt_s: 0.001\npairs: 3\n").find("volume"), std::string::npos);
  // A box far beyond any integer voxel count is named by its count, not converted out of range.
  const std::string huge =
      error_of("dt_s: 0.001\nvolume: {x_mm: [-1e300, 1e300], y_mm: [-1, 1], z_mm: [0, 1], voxel_mm: 1}\n");
  EXPECT_NE(huge.find("2e+300 voxels along x (1..100000)"), std::string::npos) << huge;
  const std::string wider =
      error_of("dt_s: 0.001\nvolume: {x_mm: [-1e308, 1e308], y_mm: [-1, 1], z_mm: [0, 1], voxel_mm: 1}\n");
  EXPECT_NE(wider.find("inf voxels along x"), std::string::npos) << wider;
  const std::string guard = error_of(
      "dt_s: 0.001\nvolume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 1e-300], voxel_mm: 1,\n"
      "voxel_z_mm: 1e-300, depth_guard_mm: 1}\n");
  EXPECT_NE(guard.find("depth_guard_mm: must be at most 100000 slices"), std::string::npos) << guard;
  // MART's ranges are recon's (one owner): the same bound whether run.yaml or process.yaml says it.
  EXPECT_NE(
      error_of(kVolume + "reconstruction: {iterations: 20000}\n").find("reconstruction.iterations: must be 1 to 10000"),
      std::string::npos)
      << error_of(kVolume + "reconstruction: {iterations: 20000}\n");
  EXPECT_NE(error_of("pairs: [3\n").find("run.yaml"), std::string::npos);  // YAML syntax
}

// A run measures the depth response of each tier that asks for it while Armed (cancellable, kept on
// disk: processing_test.cpp); either tier takes the setting, and its range is core/process's.
TEST(RunConfig, EitherTierTakesADepthResponse) {
  EXPECT_EQ(parse_run_config(kVolume + "reconstruction: {depth_response_ppm: 0.5}\n", "run.yaml")
                .spec.full.depth_response_ppm,
            0.5);
  const RunConfig live = parse_run_config(kVolume + "live: {reconstruction: {depth_response_ppm: 0.25}}\n", "run.yaml");
  ASSERT_TRUE(live.spec.live);
  EXPECT_EQ(live.spec.live->depth_response_ppm, 0.25);
  EXPECT_EQ(live.spec.full.depth_response_ppm, 0.0);
  const std::string bad = error_of(kVolume + "reconstruction: {depth_response_ppm: 9}\n");
  EXPECT_NE(bad.find("run.yaml: reconstruction.depth_response_ppm"), std::string::npos) << bad;
}

// process.yaml, as the run folder keeps it and `plenopiv process --run` reads it: the same spec the
// live stage used, key for key.
TEST(RunConfig, ProcessYamlGivesCoreProcessTheSameSpec) {
  for (const std::string& volume :
       {std::string("volume: {x_mm: [-1, 1], y_mm: [-2, 2], z_mm: [0, 2], voxel_mm: 0.5}\n"),
        std::string("volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [-2, 2], voxel_mm: 0.125}\n"),
        std::string("volume: {x_mm: [-0.3, 0.71], y_mm: [0.1, 1.3], z_mm: [-1.7, 0.2], voxel_mm: 0.1, "
                    "depth_guard_mm: 0.25}\n")}) {
    const RunConfig c = parse_run_config(
        "dt_s: 0.0004\n" + volume +
            "reconstruction: {iterations: 2, mu: 0.7}\n"
            "correlation: {passes: [{window: 4, overlap_percent: 50}]}\nlive: {reconstruction: {iterations: 1}}\n",
        "run.yaml");
    const process::ProcessSpec s =
        process::process_spec_from(YamlMap(load_yaml_text(c.process_yaml(), "process.yaml"), "process.yaml"));
    EXPECT_EQ(s.full.grid, c.volume_grid()) << volume;
    EXPECT_DOUBLE_EQ(s.full.correlation.dt_s, 4e-4);
    EXPECT_EQ(s.full.mart.iterations, 2);
    EXPECT_DOUBLE_EQ(s.full.mart.mu, 0.7);
    EXPECT_EQ(s.full.correlation.passes.size(), 1u);
    EXPECT_DOUBLE_EQ(s.full.depth_guard_mm, c.spec.full.depth_guard_mm);
    ASSERT_TRUE(s.live);
    EXPECT_EQ(s.live->mart.iterations, 1);
  }
  EXPECT_NE(error_of(kVolume.substr(0, kVolume.find("voxel_mm: 0.5}")) + "voxel_mm: 0.5, depth_guard_mm: -1}\n")
                .find("volume.depth_guard_mm"),
            std::string::npos);
}

// The quality lane: on (newest) by default when the spec has a live tier, off without one; `every: N`
// and `off` as written; asking for one without a live tier, or a bad policy, names the key.
TEST(RunConfig, TheQualityLaneFollowsTheLiveTierAndItsPolicyIsParsedOnce) {
  const std::string live = "live: {reconstruction: {iterations: 1}}\n";
  EXPECT_FALSE(parse_run_config(kVolume, "run.yaml").quality.on());
  EXPECT_EQ(parse_run_config(kVolume, "run.yaml").live_lane_tier(), process::Tier::full);
  const RunConfig two = parse_run_config(kVolume + live, "run.yaml");
  EXPECT_EQ(two.quality.take, QualityLane::Take::newest);
  EXPECT_EQ(two.quality.queue, 2);
  EXPECT_EQ(two.live_lane_tier(), process::Tier::live);
  const RunConfig every = parse_run_config(kVolume + live + "quality: {every: 5}\nquality_queue: 4\n", "run.yaml");
  EXPECT_EQ(every.quality.take, QualityLane::Take::every);
  EXPECT_EQ(every.quality.every, 5u);
  EXPECT_EQ(every.quality.queue, 4);
  EXPECT_EQ(every.quality.policy(), "every 5");
  EXPECT_FALSE(parse_run_config(kVolume + live + "quality: off\n", "run.yaml").quality.on());

  EXPECT_NE(error_of(kVolume + "quality: newest\n").find("quality: a quality lane needs a live: tier"),
            std::string::npos)
      << error_of(kVolume + "quality: newest\n");
  EXPECT_NE(error_of(kVolume + live + "quality: oldest\n").find("quality"), std::string::npos);
  EXPECT_NE(error_of(kVolume + live + "quality: {every: 0}\n").find("quality.every: must be in [1, 2^31]"),
            std::string::npos)
      << error_of(kVolume + live + "quality: {every: 0}\n");
  EXPECT_NE(error_of(kVolume + live + "quality: {evry: 2}\n").find("quality.evry: unknown key"), std::string::npos)
      << error_of(kVolume + live + "quality: {evry: 2}\n");
  EXPECT_NE(error_of(kVolume + live + "quality_queue: 0\n").find("quality_queue"), std::string::npos);
}

// The alignment preview: none unless asked; its interval, downsampling and depth as written, each
// checked by name.
TEST(RunConfig, ThePreviewIsOffUnlessAskedAndItsSettingsAreChecked) {
  EXPECT_FALSE(parse_run_config(kVolume, "run.yaml").preview.on());
  const RunConfig on = parse_run_config(kVolume + "preview: {}\n", "run.yaml");
  EXPECT_TRUE(on.preview.on());
  EXPECT_DOUBLE_EQ(on.preview.interval_s, 1.0);
  EXPECT_EQ(on.preview.downsample, 8);
  const RunConfig set = parse_run_config(kVolume + "preview: {interval_s: 5, downsample: 4, z_mm: -1.5}\n", "run.yaml");
  EXPECT_DOUBLE_EQ(set.preview.interval_s, 5.0);
  EXPECT_EQ(set.preview.downsample, 4);
  EXPECT_DOUBLE_EQ(set.preview.z_mm, -1.5);
  EXPECT_NE(error_of(kVolume + "preview: {downsample: 0}\n").find("preview.downsample"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "preview: {z_mm: 2000}\n").find("preview.z_mm: must be in [-1000, 1000] mm"),
            std::string::npos)
      << error_of(kVolume + "preview: {z_mm: 2000}\n");
  EXPECT_NE(error_of(kVolume + "preview: {rate: 1}\n").find("preview.rate: unknown key"), std::string::npos);
}

TEST(RunConfig, TheCameraRegionIsTheWholeSensorUnlessGivenAndItsSizeIsRequired) {
  const drivers::Roi whole = parse_run_config(kVolume, "run.yaml").camera_roi;
  EXPECT_EQ(whole.x + whole.y + whole.width + whole.height, 0);
  const drivers::Roi roi =
      parse_run_config(kVolume + "camera_roi: {x: 16, y: 8, width: 256, height: 128}\n", "run.yaml").camera_roi;
  EXPECT_EQ(roi.x, 16);
  EXPECT_EQ(roi.y, 8);
  EXPECT_EQ(roi.width, 256);
  EXPECT_EQ(roi.height, 128);
  const drivers::Roi corner =
      parse_run_config(kVolume + "camera_roi: {width: 64, height: 32}\n", "run.yaml").camera_roi;
  EXPECT_EQ(corner.x + corner.y, 0);
  EXPECT_NE(error_of(kVolume + "camera_roi: {width: 64}\n").find("camera_roi.height: is required"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "camera_roi: {x: -1, width: 64, height: 64}\n").find("camera_roi.x: must be 0 to"),
            std::string::npos);
  EXPECT_NE(error_of(kVolume + "camera_roi: {width: 0, height: 64}\n").find("camera_roi.width: must be 1 to"),
            std::string::npos);
  EXPECT_NE(error_of(kVolume + "camera_roi: {w: 64, width: 64, height: 64}\n").find("camera_roi.w: unknown key"),
            std::string::npos);
  EXPECT_NE(error_of(kVolume + "camera_roi: [0, 0, 64, 64]\n").find("camera_roi"), std::string::npos);
}

}  // namespace
}  // namespace plenopiv::daemon
