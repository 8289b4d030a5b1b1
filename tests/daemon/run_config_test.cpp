// run.yaml: the shipped default parses; wrong keys and values are errors that name the key.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "core/base/errors.hpp"
#include "core/process/process.hpp"
#include "daemon/run_config.hpp"

namespace plenopiv::daemon {
namespace {

const std::string kVolume = "volume: {x_mm: [-1, 1], y_mm: [-2, 2], z_mm: [0, 1], voxel_mm: 0.5}\n";

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
  EXPECT_DOUBLE_EQ(c.dt_s, 1e-4);
  EXPECT_TRUE(c.camera_uri.empty());  // the daemon's default camera
  EXPECT_EQ(c.reconstruction["iterations"].as<int>(), 3);
  EXPECT_EQ(c.correlation["passes"][0]["window"].as<int>(), 16);
  const process::ProcessSettings s =
      process::process_settings_from(YamlMap(load_yaml_text(c.process_yaml(), "process.yaml"), "process.yaml"));
  ASSERT_EQ(s.correlation.passes.size(), 2u);
  EXPECT_EQ(s.correlation.passes[0].depth_margin, 4);  // depth motion recovered twice over (benchmarks.md)
  EXPECT_EQ(s.correlation.passes[1].window, (std::array<int, 3>{8, 8, 8}));
  EXPECT_EQ(s.correlation.depth_prefilter, 4);
  EXPECT_EQ(s.correlation.final_smoothing, 1);
  EXPECT_FALSE(c.publish_volumes);
  EXPECT_EQ(c.text, text.str());
}

// The paper-scale live config gives core/process the paper's box and the setting measured to fit
// 30 s per pair (docs/benchmarks.md, "Paper scale: time against error").
TEST(RunConfig, ShippedPaperScaleConfigParses) {
  std::ifstream in(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/run-paper.yaml");
  std::stringstream text;
  text << in.rdbuf();
  const RunConfig c = parse_run_config(text.str(), "run-paper.yaml");
  EXPECT_EQ(c.max_pairs_in_flight, 1);
  const process::ProcessSettings s =
      process::process_settings_from(YamlMap(load_yaml_text(c.process_yaml(), "process.yaml"), "process.yaml"));
  EXPECT_EQ(s.grid.shape, (std::array<int, 3>{300, 200, 200}));
  EXPECT_EQ(s.grid.spacing_mm, (std::array<double, 3>{0.125, 0.125, 0.125}));
  EXPECT_EQ(s.mart.iterations, 8);
  EXPECT_DOUBLE_EQ(s.mart.mu, 1.0);
  EXPECT_TRUE(s.mart.accelerate);
  ASSERT_EQ(s.correlation.passes.size(), 5u);  // core/piv's default with a third 16^3, 50 % pass
  EXPECT_EQ(s.correlation.passes[1].depth_margin, 4);
  EXPECT_EQ(s.correlation.passes[4].window, (std::array<int, 3>{16, 16, 16}));
  EXPECT_DOUBLE_EQ(s.correlation.passes[4].overlap_percent, 75.0);
  EXPECT_DOUBLE_EQ(s.correlation.intensity_threshold_of_mean, 3.0);
  EXPECT_EQ(s.correlation.depth_prefilter, 4);
  EXPECT_EQ(s.correlation.final_smoothing, 1);
}

TEST(RunConfig, VolumeGridCoversTheExtent) {
  const RunConfig c = parse_run_config(kVolume, "run.yaml");
  const Grid3 g = c.volume_grid();
  EXPECT_EQ(g.shape, (std::array<int, 3>{5, 9, 3}));
  EXPECT_EQ(g.origin_mm, (std::array<double, 3>{-1, -2, 0}));
  EXPECT_EQ(g.spacing_mm, (std::array<double, 3>{0.5, 0.5, 0.5}));
  EXPECT_EQ(c.pair_count, 0u);  // until stopped
  EXPECT_TRUE(c.reconstruction.IsMap());
}

TEST(RunConfig, UnknownKeyIsNamed) {
  const std::string e = error_of(kVolume + "pairz: 3\n");
  EXPECT_NE(e.find("run.yaml: pairz: unknown key"), std::string::npos) << e;
}

TEST(RunConfig, UnknownVolumeKeyIsNamedWithItsPath) {
  const std::string e =
      error_of("volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 1], voxel: 0.5}\n");
  EXPECT_NE(e.find("volume.voxel: unknown key"), std::string::npos) << e;
}

TEST(RunConfig, BadValuesAreNamed) {
  EXPECT_NE(error_of(kVolume + "pairs: -1\n").find("pairs: must be >= 0"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "rate_hz: 0\n").find("rate_hz"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "rate_hz: 10\ndt_s: 0.2\n").find("dt_s"), std::string::npos);
  EXPECT_NE(error_of(kVolume + "reconstruction: 3\n").find("reconstruction: expected a mapping"),
            std::string::npos);
  EXPECT_NE(error_of(kVolume + "max_pairs_in_flight: 0\n").find("max_pairs_in_flight"),
            std::string::npos);
  EXPECT_NE(error_of("volume: {x_mm: [1, -1], y_mm: [-1, 1], z_mm: [0, 1], voxel_mm: 1}\n")
                .find("volume.x_mm: max must be greater than min"),
            std::string::npos);
  EXPECT_NE(error_of("volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 1]}\n").find("voxel_mm"),
            std::string::npos);
  EXPECT_NE(error_of("pairs: 3\n").find("volume"), std::string::npos);
  EXPECT_NE(error_of("pairs: [3\n").find("run.yaml"), std::string::npos);  // YAML syntax
}

// process.yaml, as the live stage and `plenopiv process --run` read it: the run's grid,
// the run's dt, its sections, and the depth guard when the run sets one.
TEST(RunConfig, ProcessYamlGivesCoreProcessTheLiveGridAndSettings) {
  for (const std::string& volume :
       {std::string("volume: {x_mm: [-1, 1], y_mm: [-2, 2], z_mm: [0, 2], voxel_mm: 0.5}\n"),
        std::string("volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [-2, 2], voxel_mm: 0.125}\n"),
        std::string("volume: {x_mm: [-0.3, 0.71], y_mm: [0.1, 1.3], z_mm: [-1.7, 0.2], voxel_mm: 0.1, "
                    "depth_guard_mm: 0.25}\n")}) {
    const RunConfig c = parse_run_config(
        "dt_s: 0.0004\n" + volume + "reconstruction: {iterations: 2, mu: 0.7}\n"
        "correlation: {passes: [{window: 4, overlap_percent: 50}]}\n", "run.yaml");
    const process::ProcessSettings s =
        process::process_settings_from(YamlMap(load_yaml_text(c.process_yaml(), "process.yaml"), "process.yaml"));
    EXPECT_EQ(s.grid.shape, c.volume_grid().shape) << volume;
    // The same voxels: exactly for binary fractions like 0.125, to a rounding of the extent's
    // midpoint otherwise (both the live stage and --run read process.yaml, so they agree exactly).
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(s.grid.origin_mm[a], c.volume_grid().origin_mm[a], 1e-12) << volume;
    EXPECT_EQ(s.grid.spacing_mm, c.volume_grid().spacing_mm) << volume;
    EXPECT_DOUBLE_EQ(s.correlation.dt_s, 4e-4);
    EXPECT_EQ(s.mart.iterations, 2);
    EXPECT_DOUBLE_EQ(s.mart.mu, 0.7);
    EXPECT_EQ(s.correlation.passes.size(), 1u);
    EXPECT_DOUBLE_EQ(s.depth_guard_mm, c.depth_guard_mm.value_or(process::ProcessSettings{}.depth_guard_mm));
  }
  EXPECT_NE(error_of(kVolume.substr(0, kVolume.size() - 2) + ", depth_guard_mm: -1}\n").find("volume.depth_guard_mm"),
            std::string::npos);
}

}  // namespace
}  // namespace plenopiv::daemon
