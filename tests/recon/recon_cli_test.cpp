// `plenopiv reconstruct` end to end: a TIFF of known particles in, HDF5 and .vti volumes out,
// progress per iteration, and clear refusals of bad arguments.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "core/calib/nominal_calibration.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "core/recon/quality.hpp"
#include "core/recon/weights.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::recon {
namespace {

using testing_support::binary;
using testing_support::run_command;

const std::string kCamera = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";

// `plenopiv reconstruct` of dir/particle.tif on the grid below, 3 iterations, into dir/output.
std::vector<std::string> reconstruct_args(const std::filesystem::path& dir, const std::string& output,
                                          const std::vector<std::string>& extra) {
  std::vector<std::string> args = {binary("plenopiv"),
                                   "reconstruct",
                                   "--camera",
                                   kCamera,
                                   (dir / "particle.tif").string(),
                                   "--extent",
                                   "-0.625",
                                   "0.625",
                                   "-0.625",
                                   "0.625",
                                   "-2",
                                   "2",
                                   "--voxel",
                                   "0.125",
                                   "--voxel-z",
                                   "0.5",
                                   "--iterations",
                                   "3",
                                   "-o",
                                   (dir / output).string()};
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

TEST(ReconstructCli, WritesVolumesWhoseBrightestVoxelIsTheParticle) {
  const auto dir = testing_support::temp_dir("recon-cli");
  // The CLI's grid for --extent -0.625 0.625 -0.625 0.625 -2 2 --voxel 0.125 --voxel-z 0.5.
  Grid3 g;
  g.shape = {10, 10, 8};
  g.spacing_mm = {0.125, 0.125, 0.5};
  g.origin_mm = {-0.5625, -0.5625, -1.75};
  const auto cam = optics::load_camera_file(kCamera);
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  const WeightingOperator op(cam, lenses, g, calib::geometric_white_image(cam, lenses));
  Volume truth(g, 0.f);
  truth.at(3, 6, 2) = 1.f;  // one particle at (-0.1875, 0.1875, -0.75) mm
  ImageF projected(850, 850, 0.f);
  op.project(truth.data, projected.pixels);
  float peak = 0;
  for (float v : projected.pixels) peak = std::max(peak, v);
  ImageU16 image(850, 850, 0);
  for (std::size_t i = 0; i < image.size(); ++i)
    image.pixels[i] = std::uint16_t(std::lround(projected.pixels[i] / peak * 60000));
  io::write_tiff(dir / "particle.tif", image);

  std::string out;
  const int status = run_command(reconstruct_args(dir, "v.h5", {}), out);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("iteration 3/3 residual"), std::string::npos) << out;
  EXPECT_NE(out.find("skipped"), std::string::npos) << out;
  EXPECT_TRUE(std::filesystem::exists(dir / "v.vti"));
  const Volume v = io::read_volume_h5(dir / "v.h5");
  ASSERT_EQ(v.grid.shape, g.shape);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(v.grid.origin_mm[a], g.origin_mm[a], 1e-9);
  const auto fit = fit_particle(v, {-0.1875, 0.1875, -0.75}, {3, 3, 3});
  ASSERT_TRUE(fit);
  EXPECT_NEAR(fit->position_mm[0], -0.1875, 0.0625);
  EXPECT_NEAR(fit->position_mm[1], 0.1875, 0.0625);
  EXPECT_NEAR(fit->position_mm[2], -0.75, 0.5);

  // --accelerate reaches MART: another volume, the particle still where it is.
  ASSERT_EQ(run_command(reconstruct_args(dir, "accelerated.h5", {"--accelerate"}), out), 0) << out;
  const Volume accelerated = io::read_volume_h5(dir / "accelerated.h5");
  EXPECT_NE(accelerated.data, v.data);
  const auto fit_accelerated = fit_particle(accelerated, {-0.1875, 0.1875, -0.75}, {3, 3, 3});
  ASSERT_TRUE(fit_accelerated);
  EXPECT_NEAR(fit_accelerated->position_mm[0], -0.1875, 0.0625);
  EXPECT_NEAR(fit_accelerated->position_mm[1], 0.1875, 0.0625);
  EXPECT_NEAR(fit_accelerated->position_mm[2], -0.75, 0.5);

  // --prune-scope reaches MART: the same threshold against each slice's peak prunes another count of
  // voxels than against the volume's (here none: each slice's live voxels are the particle's own),
  // and the particle stays. --prune-depth-reach: RefusesBadArgumentsClearly.
  const auto pruned_with = [&](std::vector<std::string> extra, const std::string& name) {
    extra.insert(extra.begin(), {"--prune-threshold", "0.3"});
    const std::vector<std::string> args = reconstruct_args(dir, name + ".h5", extra);
    EXPECT_EQ(run_command(args, out), 0) << out;
    const auto at = out.find(" voxels pruned)");
    EXPECT_NE(at, std::string::npos) << out;
    const auto from = out.rfind('(', at);
    return out.substr(from + 1, at - from - 1);
  };
  const std::string by_volume = pruned_with({}, "pruned-volume");
  const std::string by_slice = pruned_with({"--prune-scope", "slice"}, "pruned-slice");
  EXPECT_NE(by_volume, by_slice) << "voxels pruned: " << by_volume << " against the volume's peak, " << by_slice
                                 << " against each slice's";
  const auto fit_slice = fit_particle(io::read_volume_h5(dir / "pruned-slice.h5"), {-0.1875, 0.1875, -0.75}, {3, 3, 3});
  ASSERT_TRUE(fit_slice);
  EXPECT_NEAR(fit_slice->position_mm[2], -0.75, 0.5);
  std::printf("voxels pruned below 0.3 of the peak: %s (the volume's), %s (each slice's)\n", by_volume.c_str(),
              by_slice.c_str());
}

TEST(ReconstructCli, RefusesBadArgumentsClearly) {
  const auto dir = testing_support::temp_dir("recon-cli");
  io::write_tiff(dir / "small.tif", ImageU16(100, 100, 5));
  std::string out;
  EXPECT_EQ(2, run_command({binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "small.tif").string(),
                            "--extent", "-1", "1", "-1", "1", "-1", "1", "-o", (dir / "x.h5").string()},
                           out));
  EXPECT_NE(out.find("850 x 850"), std::string::npos) << out;
  EXPECT_EQ(2, run_command({binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "small.tif").string(),
                            "--extent", "1", "-1", "-1", "1", "-1", "1", "-o", (dir / "x.h5").string()},
                           out));
  EXPECT_NE(out.find("--extent"), std::string::npos) << out;
  io::write_tiff(dir / "right.tif", ImageU16(850, 850, 5));
  EXPECT_EQ(
      2, run_command({binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "right.tif").string(), "--extent",
                      "-1", "1", "-1", "1", "-1", "1", "--sensor-blur-mm", "-0.001", "-o", (dir / "x.h5").string()},
                     out));
  EXPECT_NE(out.find("sensor_blur_sigma_mm"), std::string::npos) << out;
  EXPECT_EQ(105, run_command(
                     {binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "right.tif").string(), "--extent",
                      "-1", "1", "-1", "1", "-1", "1", "--prune-scope", "brick", "-o", (dir / "x.h5").string()},
                     out));
  EXPECT_NE(out.find("--prune-scope"), std::string::npos) << out;
  EXPECT_EQ(
      105, run_command({binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "right.tif").string(),
                        "--extent", "-1", "1", "-1", "1", "-1", "1", "--start", "zeros", "-o", (dir / "x.h5").string()},
                       out));
  EXPECT_NE(out.find("--start"), std::string::npos) << out;
  EXPECT_EQ(
      2, run_command({binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "right.tif").string(), "--extent",
                      "-1", "1", "-1", "1", "-1", "1", "--prune-depth-reach", "99", "-o", (dir / "x.h5").string()},
                     out));
  EXPECT_NE(out.find("prune_depth_reach"), std::string::npos) << out;
  EXPECT_EQ(
      2, run_command({binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "right.tif").string(), "--extent",
                      "-1", "1", "-1", "1", "-1", "1", "--prune-local-threshold", "1", "-o", (dir / "x.h5").string()},
                     out));
  EXPECT_NE(out.find("prune_local_threshold"), std::string::npos) << out;
  EXPECT_EQ(
      2, run_command({binary("plenopiv"), "reconstruct", "--camera", kCamera, (dir / "right.tif").string(), "--extent",
                      "-1", "1", "-1", "1", "-1", "1", "--mlos-power", "0.5", "-o", (dir / "x.h5").string()},
                     out));
  EXPECT_NE(out.find("mlos_power"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "x.h5"));
}

}  // namespace
}  // namespace plenopiv::recon
