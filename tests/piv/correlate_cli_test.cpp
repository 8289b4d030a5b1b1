// `plenopiv correlate` end to end: volume files in, vector field files out, bad input refused.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "core/io/hdf5_files.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

using testing_support::binary;
using testing_support::run_command;

std::filesystem::path dir() { return testing_support::temp_dir("piv-cli"); }

Grid3 grid(int nx) {
  Grid3 g;
  g.shape = {nx, 48, 48};
  g.spacing_mm = {0.1, 0.1, 0.1};
  g.origin_mm = {-2.0, -2.4, 1.0};
  return g;
}

// A pair of exact-particle volumes moved by (0.12, -0.05, 0.03) mm, written as HDF5.
void write_pair(const Grid3& g, const std::filesystem::path& a, const std::filesystem::path& b) {
  const sim::Box box{{-2.4, -2.8, 0.6}, {g.origin_mm[0] + (g.shape[0] + 3) * 0.1, 2.6, 6.2}};
  const auto pa = sim::random_particles(box, 700, 3);
  const sim::UniformFlow flow({0.12, -0.05, 0.03});
  io::write_volume_h5(a, sim::render_exact_volume(g, pa));
  io::write_volume_h5(b, sim::render_exact_volume(g, sim::displace(pa, flow)));
}

TEST(CorrelateCli, WritesTheVectorFieldAndVti) {
  const auto a = dir() / "a.h5", b = dir() / "b.h5", out = dir() / "field.h5", vti = dir() / "field.vti";
  write_pair(grid(48), a, b);
  std::string output;
  const int status = run_command({binary("plenopiv"), "correlate", a.string(), b.string(), "-o", out.string(), "--vti",
                                  vti.string(), "--dt", "0.002", "--passes", "24@50,16@50,16@50"},
                                 output);
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find("pass 3/3"), std::string::npos) << output;
  const VectorField f = io::read_vector_field_h5(out);
  EXPECT_EQ(f.dt_s, 0.002);
  EXPECT_EQ(f.grid.shape, (std::array<int, 3>{5, 5, 5}));
  // Window centres: first window starts at voxel 0 and spans 16 voxels -> centre 7.5 voxels.
  EXPECT_NEAR(f.grid.origin_mm[0], -2.0 + 0.75, 1e-9);
  EXPECT_NEAR(f.grid.spacing_mm[2], 0.8, 1e-9);
  for (std::size_t i = 0; i < f.grid.count(); ++i) {
    ASSERT_TRUE(f.valid[i]);
    EXPECT_NEAR(f.dx_mm[i], 0.12, 0.01);
    EXPECT_NEAR(f.dy_mm[i], -0.05, 0.01);
    EXPECT_NEAR(f.dz_mm[i], 0.03, 0.01);
  }
  // h5py sees velocities in m/s and the vorticity fields (zero for a uniform flow).
  std::string py;
  const int py_status = run_command(
      {"/usr/bin/python3", "-c",
       "import h5py,numpy as np; g=h5py.File('" + out.string() +
           "')['vectors'];"
           "print(round(float(np.median(g['u'][...])),2), float(np.nanmax(np.abs(g['vorticity_z'][...]))) < 5)"},
      py);
  ASSERT_EQ(py_status, 0) << py;
  EXPECT_NE(py.find("0.06 True"), std::string::npos) << py;  // 0.12 mm / 2 ms = 0.06 m/s
  std::ifstream v(vti);
  std::string head(400, '\0');
  v.read(head.data(), 400);
  EXPECT_NE(head.find("ImageData"), std::string::npos);
}

TEST(CorrelateCli, DifferentGridsAreAClearError) {
  const auto a = dir() / "a48.h5", b = dir() / "b48.h5", c = dir() / "c56.h5", d = dir() / "d56.h5";
  write_pair(grid(48), a, b);
  write_pair(grid(56), c, d);
  std::string output;
  const int status = run_command(
      {binary("plenopiv"), "correlate", a.string(), c.string(), "-o", (dir() / "never.h5").string(), "--dt", "0.001"},
      output);
  EXPECT_EQ(status, 2) << output;
  EXPECT_NE(output.find("different grids"), std::string::npos) << output;
  EXPECT_FALSE(std::filesystem::exists(dir() / "never.h5"));
}

TEST(CorrelateCli, MissingDtAndBadPassesAreRefused) {
  const auto a = dir() / "a2.h5", b = dir() / "b2.h5";
  write_pair(grid(48), a, b);
  std::string output;
  EXPECT_EQ(
      run_command({binary("plenopiv"), "correlate", a.string(), b.string(), "-o", (dir() / "x.h5").string()}, output),
      2);
  EXPECT_NE(output.find("--dt"), std::string::npos) << output;
  EXPECT_EQ(run_command({binary("plenopiv"), "correlate", a.string(), b.string(), "-o", (dir() / "x.h5").string(),
                         "--dt", "1", "--passes", "16"},
                        output),
            2);
  EXPECT_NE(output.find("--passes"), std::string::npos) << output;
  EXPECT_EQ(run_command({binary("plenopiv"), "correlate", a.string(), b.string(), "-o", (dir() / "x.h5").string(),
                         "--dt", "1", "--final-smoothing", "5"},
                        output),
            2);
  EXPECT_NE(output.find("final_smoothing"), std::string::npos) << output;
  EXPECT_EQ(run_command({binary("plenopiv"), "correlate", a.string(), b.string(), "-o", (dir() / "x.h5").string(),
                         "--dt", "1", "--depth-prefilter", "9"},
                        output),
            2);
  EXPECT_NE(output.find("depth_prefilter: must be 0 to 8, got 9"), std::string::npos) << output;
  EXPECT_EQ(run_command({binary("plenopiv"), "correlate", a.string(), b.string(), "-o", (dir() / "x.h5").string(),
                         "--dt", "1", "--depth-prefilter", "2", "--no-prefilter"},
                        output),
            2);
  EXPECT_NE(output.find("the prefilter, which is off"), std::string::npos) << output;
  EXPECT_FALSE(std::filesystem::exists(dir() / "x.h5"));
}

// One pair correlated twice (passes 24@50,16@75, dt 2 ms), as it is and with `flags`; files named
// after `name`. Both runs must succeed: their fields and what each printed.
struct PlainAndWith {
  VectorField plain, with;
  std::string plain_output, with_output;
};
PlainAndWith correlate_plain_and_with(const std::string& name, const std::vector<std::string>& flags) {
  const auto a = dir() / (name + "_a.h5"), b = dir() / (name + "_b.h5");
  const auto plain = dir() / (name + "_plain.h5"), with = dir() / (name + "_with.h5");
  write_pair(grid(48), a, b);
  PlainAndWith r;
  std::vector<std::string> command{binary("plenopiv"), "correlate",   a.string(), b.string(), "--dt", "0.002",
                                   "--passes",         "24@50,16@75", "-o"};
  command.push_back(plain.string());
  EXPECT_EQ(run_command(command, r.plain_output), 0) << r.plain_output;
  command.back() = with.string();
  command.insert(command.end(), flags.begin(), flags.end());
  EXPECT_EQ(run_command(command, r.with_output), 0) << r.with_output;
  r.plain = io::read_vector_field_h5(plain);
  r.with = io::read_vector_field_h5(with);
  return r;
}

// --depth-prefilter: the run says so, and the field is still the uniform shift, measured through
// volumes smoothed in depth (so not the same bits as without).
TEST(CorrelateCli, DepthPrefilterIsAppliedAndReported) {
  const PlainAndWith r = correlate_plain_and_with("depth", {"--depth-prefilter", "3"});
  EXPECT_EQ(r.plain_output.find("along depth"), std::string::npos) << r.plain_output;
  EXPECT_NE(r.with_output.find("prefilter: 3 more binomial passes along depth (z)"), std::string::npos)
      << r.with_output;
  ASSERT_EQ(r.plain.grid, r.with.grid);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < r.plain.grid.count(); ++i) {
    ASSERT_TRUE(r.with.valid[i]);
    EXPECT_NEAR(r.with.dx_mm[i], 0.12, 0.01);
    differ += r.plain.dx_mm[i] != r.with.dx_mm[i];
  }
  EXPECT_GT(differ, r.plain.grid.count() / 2);
}

// --final-smoothing: the run says so, and the field is the same uniform shift (a uniform field is
// left as it is; only its noise drops).
TEST(CorrelateCli, FinalSmoothingIsAppliedAndReported) {
  const PlainAndWith r = correlate_plain_and_with("smooth", {"--final-smoothing", "2"});
  EXPECT_EQ(r.plain_output.find("smoothing pass"), std::string::npos) << r.plain_output;
  EXPECT_NE(r.with_output.find("final field: 2 binomial smoothing passes"), std::string::npos) << r.with_output;
  const VectorField &p = r.plain, &s = r.with;
  ASSERT_EQ(p.grid, s.grid);
  double spread_p = 0, spread_s = 0;
  std::size_t differ = 0;
  for (std::size_t i = 0; i < p.grid.count(); ++i) {
    ASSERT_TRUE(p.valid[i] && s.valid[i]);
    EXPECT_NEAR(s.dx_mm[i], 0.12, 0.01);
    spread_p += std::pow(p.dx_mm[i] - 0.12, 2);
    spread_s += std::pow(s.dx_mm[i] - 0.12, 2);
    differ += p.dx_mm[i] != s.dx_mm[i];
  }
  EXPECT_GT(differ, p.grid.count() / 2);  // smoothed inside, not only at the faces
  EXPECT_LT(spread_s, spread_p);
}

}  // namespace
}  // namespace plenopiv
