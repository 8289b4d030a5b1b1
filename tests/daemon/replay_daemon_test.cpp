// plenopivd with the replay camera: a run driven by the run's trigger records the replayed frames
// bit for bit; replay URIs reach only folders under the replay_dir named at start.
#include <gtest/gtest.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <thread>

#include "core/io/tiff.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/daemon_status.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::ChildProcess;

// Frame `k`: 850 x 850 px (the small camera), a pattern no other frame has.
ImageU16 frame_image(int k) {
  ImageU16 image(850, 850);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    image.pixels[i] = std::uint16_t(((i * 7919u + std::size_t(k) * 104729u) % 4096u));
  }
  return image;
}

TEST(DaemonReplay, ARunOnTheReplayCameraRecordsTheReplayedFramesBitForBit) {
  const fs::path dir = testing_support::temp_dir("replay-daemon");
  fs::remove_all(dir / "recordings");
  fs::remove_all(dir / "data");
  fs::create_directories(dir / "recordings/rec");
  for (int k = 0; k < 3; ++k) {
    io::write_tiff(dir / "recordings/rec" / ("frame-" + std::to_string(2 * k) + ".tif"), frame_image(2 * k), false);
    io::write_tiff(dir / "recordings/rec" / ("frame-" + std::to_string(2 * k + 1) + ".tif"), frame_image(2 * k + 1),
                   false);
  }
  const std::string control = testing_support::ipc_endpoint("control");
  ChildProcess daemon(
      {testing_support::binary("plenopivd"), "--simulation", "--camera-file",
       std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml", "--replay-dir",
       (dir / "recordings").string(), "--control", control, "--publish",
       "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port()), "--data-dir", (dir / "data").string()},
      dir / "plenopivd.log");
  for (int i = 0; i < 100 && !testing_support::probe_status(control); ++i)
    ASSERT_TRUE(daemon.running()) << daemon.output();
  const auto run = [&](const std::string& camera_uri, std::string& out) {
    std::ofstream(dir / "replay.yaml") << "camera_uri: \"" << camera_uri << "\"\npairs: 3\nrate_hz: 5\ndt_s: 0.0001\n"
                                       << "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-1, 1], voxel_mm: 0.25}\n"
                                          "reconstruction: {iterations: 1}\n"
                                          "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n";
    return testing_support::run_command({testing_support::binary("plenopiv"), "--endpoint", control, "run", "start",
                                         "--config", (dir / "replay.yaml").string()},
                                        out);
  };
  std::string out;
  // Only folders under replay_dir: the data folder beside it is refused, naming the URI.
  EXPECT_NE(run("replay://../data", out), 0) << out;
  EXPECT_NE(out.find("replay://../data"), std::string::npos) << out;
  EXPECT_NE(out.find("outside replay_dir"), std::string::npos) << out;

  ASSERT_EQ(run("replay://rec", out), 0) << out;
  std::optional<msg::Status> s;
  for (int i = 0; i < 600; ++i) {
    std::this_thread::sleep_for(50ms);
    s = testing_support::probe_status(control);
    if (s && s->state() == "Idle" && s->pairs_recorded() >= 3) break;
  }
  ASSERT_TRUE(s);
  ASSERT_EQ(s->state(), "Idle") << daemon.output();
  const fs::path folder = testing_support::only_run_folder(dir / "data");
  const msg::RunManifest m = testing_support::read_manifest(folder);
  EXPECT_EQ(m.state(), "complete");
  EXPECT_EQ(m.frames_lost(), 0u);
  ASSERT_EQ(m.pairs_size(), 3);
  // The run's simulated trigger fired the camera through its trigger input, pair by pair.
  EXPECT_EQ(m.camera_triggering().rfind("external: camera line of sim://", 0), 0u) << m.camera_triggering();
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(io::read_tiff_u16(folder / m.pairs(k).frame_a()).pixels, frame_image(2 * k).pixels) << "pair " << k;
    EXPECT_EQ(io::read_tiff_u16(folder / m.pairs(k).frame_b()).pixels, frame_image(2 * k + 1).pixels) << "pair " << k;
  }
  daemon.signal(SIGTERM);
  EXPECT_TRUE(daemon.wait(10s).has_value());
}

}  // namespace
}  // namespace plenopiv
