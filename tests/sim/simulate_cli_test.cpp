// `plenopiv simulate` run as a real child process: outputs on disk, and clear errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "core/base/yaml_access.hpp"
#include "core/io/tiff.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particle_file.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

namespace fs = std::filesystem;
using testing_support::binary;
using testing_support::run_command;

const std::string camera = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";
fs::path dir() { return testing_support::temp_dir("simulate-cli"); }

int simulate(std::vector<std::string> args, std::string& out) {
  args.insert(args.begin(), {binary("plenopiv"), "simulate"});
  return run_command(args, out);
}

void write(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }

TEST(SimulateCli, ParticleListToTiff) {
  // On the axis of lens (20, 31) at the focal plane (x_o = c / M, M = -1): c = (-3.0625 +
  // 20 * 0.125, -3.0625 + 31 * 0.125) = (-0.5625, 0.8125) mm.
  write(dir() / "one.csv", "x [mm], y [mm], z [mm]\n0.5625,-0.8125,0\n");
  std::string out;
  ASSERT_EQ(simulate({"particles", "--camera", camera, "--particles", (dir() / "one.csv").string(), "--rays", "5000",
                      "-o", (dir() / "one.tif").string()},
                     out),
            0)
      << out;
  const ImageU16 img = io::read_tiff_u16(dir() / "one.tif");
  ASSERT_EQ(img.width, 850);
  ASSERT_EQ(img.height, 850);
  double sum = 0, sx = 0, sy = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      sum += img.at(x, y);
      sx += double(img.at(x, y)) * x;
      sy += double(img.at(x, y)) * y;
    }
  EXPECT_EQ(sum, 5000);  // the default sensor counts every landed ray once
  // Spot of lens (20, 31): column = c (1 + f_l/s_i) / pitch + 424.5.
  EXPECT_NEAR(sx / sum, -0.5625 * 1.005 / 0.0074 + 424.5, 0.15);
  EXPECT_NEAR(sy / sum, 0.8125 * 1.005 / 0.0074 + 424.5, 0.15);
}

TEST(SimulateCli, CalibrationAndWhiteImages) {
  std::string out;
  for (const std::string kind : {"calibration", "white"}) {
    const fs::path file = dir() / (kind + ".tif");
    const std::string rays = kind == "white" ? "2000" : "300";  // enough to light each disk's pixels
    ASSERT_EQ(simulate({kind, "--camera", camera, "--rays-per-lens", rays, "-o", file.string()}, out), 0) << out;
    const ImageU16 img = io::read_tiff_u16(file);
    int lit = 0;
    for (auto v : img.pixels) lit += v > 0;
    // Calibration: 2500 spots of 2.1 px across blurred by the 0.7 px diffraction jitter (4 to 40
    // lit px per lens); white: 2500 disks of 224 px^2 (of 722 500 px).
    if (kind == "calibration") {
      EXPECT_GT(lit, 2500 * 4) << "measured 24 lit px per lens";
      EXPECT_LT(lit, 2500 * 40) << "measured 24 lit px per lens";
    } else {
      EXPECT_GT(lit, 2500 * 200);
    }
  }
}

TEST(SimulateCli, CalibrationOfAnImperfectArrayWithItsTruth) {
  std::string out;
  const fs::path img = dir() / "cal-jitter.tif", truth = dir() / "cal-truth.csv";
  ASSERT_EQ(simulate({"calibration", "--camera", camera, "--rays-per-lens", "1000", "--lens-jitter-mm", "0.004",
                      "--array-rotation-rad", "0.003", "--array-offset-mm", "0.01,-0.02", "--truth", truth.string(),
                      "-o", img.string()},
                     out),
            0)
      << out;
  const ImageU16 cal = io::read_tiff_u16(img);
  std::ifstream in(truth);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "i,j,centre_x_mm,centre_y_mm,spot_column,spot_row");
  int rows = 0;
  double worst = 0;
  while (std::getline(in, line)) {
    ++rows;
    int i, j;
    double cx, cy, col, row;
    ASSERT_EQ(std::sscanf(line.c_str(), "%d,%d,%lf,%lf,%lf,%lf", &i, &j, &cx, &cy, &col, &row), 6) << line;
    if (i < 2 || j < 2 || i > 47 || j > 47) continue;
    double s = 0, sx = 0, sy = 0;
    for (int y = int(row) - 4; y <= int(row) + 5; ++y)
      for (int x = int(col) - 4; x <= int(col) + 5; ++x) {
        s += cal.at(x, y);
        sx += double(cal.at(x, y)) * x;
        sy += double(cal.at(x, y)) * y;
      }
    worst = std::max(worst, std::hypot(sx / s - col, sy / s - row));
  }
  EXPECT_EQ(rows, 2500);
  // The spots sit where the truth file says (1000 rays per lens here: a noisier centroid than the
  // library test's 3000).
  EXPECT_LT(worst, 0.2) << "measured 0.124 px";
}

TEST(SimulateCli, FramePairWithItsTruth) {
  std::string out;
  const fs::path pair = dir() / "pair";
  ASSERT_EQ(simulate({"pair", "--camera", camera, "--count", "200", "--uniform", "0.1,-0.05,0.2", "--rays", "500",
                      "--seed", "7", "-o", pair.string()},
                     out),
            0)
      << out;
  for (const char* f :
       {"frame_A.tif", "frame_B.tif", "particles_A.csv", "particles_B.csv", "flow.yaml", "simulation.yaml"}) {
    EXPECT_TRUE(fs::exists(pair / f)) << f;
  }
  const auto a = sim::read_particles_csv(pair / "particles_A.csv");
  const auto b = sim::read_particles_csv(pair / "particles_B.csv");
  ASSERT_EQ(a.size(), 200u);
  ASSERT_EQ(b.size(), 200u);
  const auto flow = sim::make_flow(YamlMap(load_yaml_file(pair / "flow.yaml"), "flow.yaml"));
  EXPECT_EQ(flow->name(), "uniform");
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_NEAR(b[k][0] - a[k][0], 0.1, 1e-12);
    EXPECT_NEAR(b[k][1] - a[k][1], -0.05, 1e-12);
    EXPECT_NEAR(b[k][2] - a[k][2], 0.2, 1e-12);
    EXPECT_EQ(flow->displacement_mm(a[k])[0], 0.1);
  }
  EXPECT_NE(io::read_tiff_u16(pair / "frame_A.tif").pixels, io::read_tiff_u16(pair / "frame_B.tif").pixels);
  // The same seed makes the same pair.
  const fs::path again = dir() / "again";
  ASSERT_EQ(simulate({"pair", "--camera", camera, "--count", "200", "--uniform", "0.1,-0.05,0.2", "--rays", "500",
                      "--seed", "7", "-o", again.string()},
                     out),
            0);
  EXPECT_EQ(io::read_tiff_u16(pair / "frame_B.tif").pixels, io::read_tiff_u16(again / "frame_B.tif").pixels);
}

// Rays emitted per frame, from `simulate pair`'s report ("<dir>/frame_A.tif: N rays, ...").
double emitted(const std::string& out, const std::string& frame) {
  const auto at = out.find(frame + ": ");
  return at == std::string::npos ? -1 : std::stod(out.substr(at + frame.size() + 2));
}

TEST(SimulateCli, PairOfParticlesThatDifferInBrightness) {
  std::string out;
  const fs::path pair = dir() / "bright";
  ASSERT_EQ(simulate({"pair", "--camera", camera, "--count", "200", "--uniform", "0.1,0,0", "--rays", "500", "--seed",
                      "7", "--brightness-spread", "1", "-o", pair.string()},
                     out),
            0)
      << out;
  // Each particle's factor is drawn from the seed and its index: both frames emit the same rays,
  // 200 x 500 times the particles' mean factor (1 on average; 1.05 measured).
  const double a = emitted(out, (pair / "frame_A.tif").string()), b = emitted(out, (pair / "frame_B.tif").string());
  EXPECT_EQ(a, b) << out;
  EXPECT_NE(a, 200.0 * 500.0) << out;
  EXPECT_NEAR(a / (200.0 * 500.0), 1.0, 0.3) << out;  // the mean of 200 factors: sd 0.09
  const YAML::Node meta = load_yaml_file(pair / "simulation.yaml");
  EXPECT_EQ(meta["brightness_spread"].as<double>(), 1.0);
  EXPECT_EQ(meta["brightness_seed"].as<std::uint64_t>(), 7u);
}

TEST(SimulateCli, BadInputIsAClearError) {
  write(dir() / "zyx.csv", "z,y,x\n1,2,3\n");
  write(dir() / "four.csv", "1,2,3,4\n");
  write(dir() / "text.csv", "x,y,z\n1,two,3\n");
  write(dir() / "tornado.yaml", "type: tornado\n");
  write(dir() / "ok.csv", "0,0,0\n");
  const std::string img = (dir() / "bad.tif").string();
  struct Case {
    std::vector<std::string> args;
    std::string message;
  } cases[] = {
      {{"particles", "--camera", camera, "--particles", (dir() / "missing.csv").string(), "-o", img},
       "missing.csv: cannot open the particle file"},
      {{"particles", "--camera", camera, "--particles", (dir() / "zyx.csv").string(), "-o", img},
       "zyx.csv: line 1: header 'z,y,x' does not name the columns x, y, z"},
      {{"particles", "--camera", camera, "--particles", (dir() / "four.csv").string(), "-o", img},
       "four.csv: line 1: expected 3 columns x,y,z (mm), found 4"},
      {{"particles", "--camera", camera, "--particles", (dir() / "text.csv").string(), "-o", img},
       "text.csv: line 2: column 2 ('two') is not a finite number"},
      {{"particles", "--camera", camera, "--particles", (dir() / "ok.csv").string(), "--rays", "-5", "-o", img},
       "--rays: must be a positive ray count, got -5"},
      {{"pair", "--camera", camera, "--count", "10", "--flow", (dir() / "tornado.yaml").string(), "-o",
        (dir() / "nopair").string()},
       "tornado.yaml: type: unknown flow 'tornado'"},
      {{"pair", "--camera", camera, "--count", "10", "--uniform", "0,0,0", "--brightness-spread", "4", "-o",
        (dir() / "nopair").string()},
       "brightness_spread: the spread of a particle's log light, 0 to 3, got 4"},
  };
  for (const Case& c : cases) {
    std::string out;
    EXPECT_EQ(simulate(c.args, out), 2) << out;
    EXPECT_NE(out.find(c.message), std::string::npos) << out;
  }
  EXPECT_FALSE(fs::exists(img));
  EXPECT_FALSE(fs::exists(dir() / "nopair"));
}

}  // namespace
}  // namespace plenopiv
