// plenopivd as a child process with a calibration file (plenopivd.yaml calibration_file): a bad
// file at start is logged and shown in status, the daemon keeps serving, and runs are refused
// naming the file until it is replaced by a good one, which the next run then uses and copies;
// what MART skipped and the black level it took off (per tile, on a two-tap sensor) in the status.
#include <gtest/gtest.h>

#include <fstream>
#include <thread>

#include "clients/cli/control_client.hpp"
#include "core/io/checksum.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/daemon_status.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using testing_support::binary;

const std::string kCameraFile = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";

int plenopiv(const std::vector<std::string>& args, std::string& out) {
  std::vector<std::string> argv{binary("plenopiv")};
  argv.insert(argv.end(), args.begin(), args.end());
  return testing_support::run_command(argv, out, 120s);
}

TEST(DaemonCalibration, ABadFileIsRefusedByNameAndAGoodOneIsUsedOnceItIsThere) {
  const fs::path dir = testing_support::temp_dir("daemon-calibration");
  fs::remove_all(dir / "data");
  // The rig's calibration, made with the offline tools on the nominal (unrotated) array.
  std::string out;
  ASSERT_EQ(plenopiv({"simulate", "calibration", "--camera", kCameraFile, "-o", (dir / "cal.tif").string()}, out), 0)
      << out;
  ASSERT_EQ(plenopiv({"simulate", "white", "--camera", kCameraFile, "-o", (dir / "white.tif").string()}, out), 0)
      << out;
  ASSERT_EQ(plenopiv({"calibrate", "--camera", kCameraFile, "--calibration-image", (dir / "cal.tif").string(),
                      "--white", (dir / "white.tif").string(), "-o", (dir / "good.h5").string()},
                     out),
            0)
      << out;
  const fs::path rig = dir / "rig.h5";  // what plenopivd.yaml names: corrupt at first
  std::ofstream(rig) << "not a calibration file";
  std::ofstream(dir / "plenopivd.yaml")
      << "camera_file: " << kCameraFile << "\ncalibration_file: rig.h5\n"
      << "data_dir: data\ncamera_uri: sim://?seed=2&ppm=0.1&rays=200\nsimulation: true\n";
  const std::string control = testing_support::ipc_endpoint("control");
  const std::string publish = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  testing_support::ChildProcess daemon(
      {binary("plenopivd"), "--config", (dir / "plenopivd.yaml").string(), "--control", control, "--publish", publish},
      dir / "plenopivd.log");
  auto status = [&] { return testing_support::probe_status(control); };
  std::optional<msg::Status> s;
  for (int i = 0; i < 100 && !(s = status()); ++i) ASSERT_TRUE(daemon.running()) << daemon.output();
  ASSERT_TRUE(s) << daemon.output();
  // Serving, and saying what is wrong and where.
  EXPECT_NE(s->processing().find("unusable at start: calibration_file: " + rig.string() + ": not an HDF5 file"),
            std::string::npos)
      << s->processing();
  EXPECT_NE(daemon.output().find("runs are refused until it is fixed"), std::string::npos) << daemon.output();

  const fs::path run_yaml = dir / "run.yaml";
  std::ofstream(run_yaml) << "pairs: 1\nrate_hz: 2\ndt_s: 0.001\n"
                             "volume: {x_mm: [-0.5, 0.5], y_mm: [-0.5, 0.5], z_mm: [-0.5, 0.5], voxel_mm: 0.125}\n"
                             "reconstruction: {iterations: 1}\n"
                             "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n";
  auto client = [&](const std::vector<std::string>& args) {
    std::vector<std::string> a{"--endpoint", control};
    a.insert(a.end(), args.begin(), args.end());
    return plenopiv(a, out);
  };
  EXPECT_NE(client({"run", "start", "--config", run_yaml.string()}), 0) << out;
  EXPECT_NE(out.find("calibration_file: " + rig.string() + ": not an HDF5 file"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "data") && !fs::is_empty(dir / "data")) << "a refused run left a folder";
  ASSERT_TRUE(daemon.running()) << daemon.output();

  // Replaced by a good file: checked again at run start, used, and copied.
  fs::copy_file(dir / "good.h5", rig, fs::copy_options::overwrite_existing);
  ASSERT_EQ(client({"run", "start", "--config", run_yaml.string()}), 0) << out;
  for (int i = 0; i < 600; ++i) {
    s = status();
    if (s && s->state() == "Idle" && s->pairs_processed() + s->pairs_skipped() >= 1) break;
    std::this_thread::sleep_for(100ms);
  }
  ASSERT_TRUE(s && s->state() == "Idle") << daemon.output();
  const fs::path run_dir = s->run_dir();
  const msg::RunManifest m = testing_support::read_manifest(run_dir);
  EXPECT_EQ(m.state(), "complete");
  EXPECT_EQ(m.calibration(), "file");
  EXPECT_EQ(m.calibration_source(), rig.string());
  EXPECT_EQ(io::read_file_bytes(run_dir / m.calibration_file()), io::read_file_bytes(dir / "good.h5"));
  EXPECT_EQ(m.pairs_processed(), 1u);
  // MART's skipped work on that pair in the status: the 8^3 box and its 1 mm guard slices at each
  // depth end (8 x 8 x 24 voxels), at most one iteration per frame (none when the sparse frames
  // light no voxel of this small box: then every update is skipped).
  ASSERT_TRUE(s->has_reconstruction()) << s->DebugString();
  const msg::ReconstructionWork& work = s->reconstruction();
  EXPECT_EQ(work.pair_index(), m.pairs(0).pair_index());
  EXPECT_EQ(work.voxels(), 8u * 8u * 24u);
  EXPECT_LE(work.live_voxels_a_size(), 1);
  EXPECT_LE(work.live_voxels_b_size(), 1);
  EXPECT_GT(work.voxel_updates_skipped(), 0.0);
  EXPECT_LE(work.voxel_updates_skipped(), 1.0);
  ASSERT_EQ(client({"status"}), 0) << out;
  EXPECT_NE(out.find("of the voxel updates skipped"), std::string::npos) << out;
  EXPECT_NE(out.find("; black level taken off A 0.0, B 0.0 counts"), std::string::npos) << out;  // ray counts alone

  // A sensor read out through two taps, the second 30 counts above the first's 20: each frame's
  // level per tile, the range in the status.
  const fs::path taps_yaml = dir / "taps.yaml";
  std::ofstream(taps_yaml) << "camera_uri: sim://?seed=2&ppm=0.1&rays=200&noise=1&tap_offset=30\n"
                           << io::read_file_bytes(run_yaml);
  ASSERT_EQ(client({"run", "start", "--config", taps_yaml.string()}), 0) << out;
  // Until the new run's pair is processed (the last run's pair took nothing off).
  for (int i = 0; i < 600; ++i) {
    s = status();
    if (s && s->state() == "Idle" && s->has_reconstruction() && s->reconstruction().black_level_a_highest() > 0) break;
    std::this_thread::sleep_for(100ms);
  }
  ASSERT_TRUE(s && s->state() == "Idle" && s->run_dir() != run_dir) << daemon.output();
  ASSERT_TRUE(s->has_reconstruction()) << s->DebugString();
  const msg::ReconstructionWork& taps = s->reconstruction();
  EXPECT_NEAR(taps.black_level_a_lowest(), 20.0, 1.0);
  EXPECT_NEAR(taps.black_level_a_highest(), 50.0, 1.0);
  EXPECT_NEAR(taps.black_level_b_lowest(), 20.0, 1.0);
  EXPECT_NEAR(taps.black_level_b_highest(), 50.0, 1.0);
  ASSERT_EQ(client({"status"}), 0) << out;
  EXPECT_NE(out.find(" (tiles 2"), std::string::npos) << out;
  daemon.signal(SIGTERM);
  EXPECT_EQ(daemon.wait(10s), 0) << daemon.output();
}

}  // namespace
}  // namespace plenopiv
