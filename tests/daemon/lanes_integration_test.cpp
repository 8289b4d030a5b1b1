// plenopivd's two lanes end to end: a real daemon (the test processing stage, whose full tier can be
// made slow) on the replay camera at 10 Hz, over real sockets: both tiers published and recorded
// apart, each lane's queue bounded and its drops counted, every raw pair recorded, and a run
// without a live tier or with the quality lane off processing on one lane.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <thread>

#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"

#include <opencv2/imgcodecs.hpp>
#include "tests/support/child_process.hpp"
#include "tests/support/daemon_status.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::binary;
using testing_support::ChildProcess;

// The processing keys of every run here; the test stage ignores them but the daemon parses them.
const std::string kProcessing =
    "dt_s: 0.001\n"
    "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 2], voxel_mm: 0.5}\n"
    "correlation: {passes: [{window: 4, overlap_percent: 50}]}\n";
const std::string kLiveTier = "live: {reconstruction: {iterations: 1}}\n";

const msg::LaneCounters* lane(const google::protobuf::RepeatedPtrField<msg::LaneCounters>& lanes,
                              const std::string& name) {
  for (const msg::LaneCounters& l : lanes) {
    if (l.name() == name) return &l;
  }
  return nullptr;
}

class Lanes : public ::testing::Test {
 protected:
  void SetUp() override {
    scratch_ = testing_support::temp_dir("lanes") / ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(scratch_);
    fs::create_directories(scratch_ / "recordings/rec");
    // Four pairs of the small camera's size, played in a loop.
    for (int k = 0; k < 8; ++k) {
      io::write_tiff(scratch_ / "recordings/rec" / ("frame-" + std::to_string(k) + ".tif"),
                     ImageU16(850, 850, std::uint16_t(100 + k)), false);
    }
  }

  // plenopivd-testcam whose full tier takes `full_tier_ms` per pair.
  void start_daemon(int full_tier_ms) {
    control_ = testing_support::ipc_endpoint("control");
    publish_ = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
    daemon_ = std::make_unique<ChildProcess>(
        std::vector<std::string>{"/usr/bin/env", "PLENOPIV_TEST_FULL_TIER_MS=" + std::to_string(full_tier_ms),
                                 binary("plenopivd-testcam"), "--simulation", "--camera-file",
                                 std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml", "--replay-dir",
                                 (scratch_ / "recordings").string(), "--control", control_, "--publish", publish_,
                                 "--data-dir", (scratch_ / "data").string()},
        scratch_ / "plenopivd.log");
    for (int i = 0; i < 100 && !testing_support::probe_status(control_); ++i)
      ASSERT_TRUE(daemon_->running()) << daemon_->output();
  }

  void TearDown() override {
    if (!daemon_) return;
    daemon_->signal(SIGTERM);
    EXPECT_TRUE(daemon_->wait(10s).has_value());
  }

  int client(const std::vector<std::string>& args, std::string& out) {
    std::vector<std::string> argv{binary("plenopiv"), "--endpoint", control_};
    argv.insert(argv.end(), args.begin(), args.end());
    return testing_support::run_command(argv, out);
  }

  int start_run(const std::string& yaml, std::string& out) {
    const fs::path path = scratch_ / "run.yaml";
    std::ofstream(path) << "camera_uri: \"replay://rec?loop=1\"\n" << yaml;
    return client({"run", "start", "--config", path.string()}, out);
  }

  // Polls status until Idle; every lane's queue depth seen on the way is checked against its bound.
  msg::Status wait_idle(std::uint32_t* deepest_quality = nullptr) {
    std::optional<msg::Status> s;
    for (int i = 0; i < 600; ++i) {
      s = testing_support::probe_status(control_);
      if (s) {
        for (const msg::LaneCounters& l : s->lanes()) {
          EXPECT_LE(l.queue_depth(), l.queue_capacity()) << l.name();
          if (deepest_quality && l.name() == "quality") *deepest_quality = std::max(*deepest_quality, l.queue_depth());
        }
        if (s->state() == "Idle" && s->pairs_recorded() > 0) return *s;
      }
      std::this_thread::sleep_for(50ms);
    }
    ADD_FAILURE() << "the run did not end: " << daemon_->output();
    return s.value_or(msg::Status{});
  }

  fs::path only_run_dir() { return testing_support::only_run_folder(scratch_ / "data"); }

  fs::path scratch_;
  std::string control_, publish_;
  std::unique_ptr<ChildProcess> daemon_;
};

TEST_F(Lanes, BothTiersArePublishedAndRecordedApartTheQueuesStayBoundedAndEveryRawPairIsRecorded) {
  // The full tier takes 300 ms a pair against a pair every 100 ms: the quality lane must drop.
  start_daemon(300);
  constexpr int n = 30;
  ChildProcess watcher({binary("plenopiv"), "watch", "--publish", publish_, "--wait", "4"}, scratch_ / "watch.log");
  std::this_thread::sleep_for(1500ms);  // the subscription reaches the publisher
  std::string out;
  ASSERT_EQ(start_run("pairs: " + std::to_string(n) +
                          "\nrate_hz: 10\nlive_queue: 2\nquality: newest\nquality_queue: 2\n" + kProcessing + kLiveTier,
                      out),
            0)
      << out;
  std::uint32_t deepest_quality = 0;
  const msg::Status status = wait_idle(&deepest_quality);

  const fs::path run = only_run_dir();
  const msg::RunManifest m = testing_support::read_manifest(run);
  EXPECT_EQ(m.state(), "complete");
  // Every raw pair recorded whatever the lanes did.
  ASSERT_EQ(m.pairs_size(), n);
  EXPECT_EQ(m.frames_lost(), 0u);
  ASSERT_EQ(m.lanes_size(), 2);
  const msg::LaneCounters* live = lane(m.lanes(), "live");
  const msg::LaneCounters* quality = lane(m.lanes(), "quality");
  ASSERT_TRUE(live && quality);
  EXPECT_EQ(live->tier(), "live");
  EXPECT_EQ(quality->tier(), "full");
  EXPECT_EQ(quality->policy(), "newest");
  EXPECT_EQ(quality->queue_capacity(), 2u);
  EXPECT_LE(deepest_quality, 2u);
  // Every pair was offered to both lanes, and each pair offered was processed or counted.
  for (const msg::LaneCounters* l : {live, quality}) {
    EXPECT_EQ(l->offered(), std::uint64_t(n)) << l->name();
    EXPECT_EQ(l->processed() + l->dropped() + l->failed() + l->cancelled(), std::uint64_t(n)) << l->name();
    EXPECT_GT(l->processed(), 0u) << l->name();
  }
  EXPECT_GT(quality->dropped(), 0u) << "the slow quality lane dropped nothing";
  EXPECT_GT(live->processed(), quality->processed());
  EXPECT_EQ(m.pairs_processed(), live->processed() + quality->processed());

  // Each tier's fields in its own files, listed in its own manifest entry; a pair processed by both
  // lanes keeps both fields (the live tier's all valid, the full tier's 3/4).
  std::uint64_t live_files = 0, full_files = 0, both = 0;
  for (const msg::ManifestPair& p : m.pairs()) {
    if (!p.live_vectors().empty()) {
      ++live_files;
      EXPECT_EQ(p.live_vectors(), "vectors/live/pair-" + std::string(6 - std::to_string(p.pair_index()).size(), '0') +
                                      std::to_string(p.pair_index()) + ".h5");
      ASSERT_TRUE(fs::exists(run / p.live_vectors())) << p.live_vectors();
    }
    if (!p.vectors().empty()) {
      ++full_files;
      ASSERT_TRUE(fs::exists(run / p.vectors())) << p.vectors();
    }
    if (!p.live_vectors().empty() && !p.vectors().empty()) {
      ++both;
      const VectorField l = io::read_vector_field_h5(run / p.live_vectors());
      const VectorField f = io::read_vector_field_h5(run / p.vectors());
      EXPECT_EQ(std::count(l.valid.begin(), l.valid.end(), 1), std::ptrdiff_t(l.valid.size()));
      EXPECT_EQ(std::count(f.valid.begin(), f.valid.end(), 1), std::ptrdiff_t(3 * f.valid.size() / 4));
    }
  }
  EXPECT_EQ(live_files, live->processed());
  EXPECT_EQ(full_files, quality->processed());
  EXPECT_GT(both, 0u);
  EXPECT_TRUE(fs::exists(run / "statistics.h5"));
  EXPECT_TRUE(fs::exists(run / "statistics-live.h5"));

  // Status carries the same lanes; `plenopiv status` shows them, and --json gives the message.
  ASSERT_EQ(status.lanes_size(), 2);
  EXPECT_EQ(lane(status.lanes(), "quality")->dropped(), quality->dropped());
  ASSERT_EQ(client({"status"}, out), 0) << out;
  EXPECT_NE(out.find("lane live      tier live, newest, queue 0/2, offered 30, processed " +
                     std::to_string(live->processed())),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("lane quality   tier full, newest, queue 0/2, offered 30, processed " +
                     std::to_string(quality->processed()) + ", dropped " + std::to_string(quality->dropped())),
            std::string::npos)
      << out;
  ASSERT_EQ(client({"status", "--json"}, out), 0) << out;
  msg::Status from_json;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(out, &from_json).ok()) << out;
  ASSERT_EQ(from_json.lanes_size(), 2);
  EXPECT_EQ(lane(from_json.lanes(), "live")->processed(), live->processed());

  // The subscriber saw fields of both tiers.
  watcher.wait(20s);
  const std::string watched = watcher.output();
  EXPECT_NE(watched.find("tier live"), std::string::npos) << watched;
  EXPECT_NE(watched.find("tier full"), std::string::npos) << watched;
}

TEST_F(Lanes, EveryNthPairGoesToTheQualityLaneInOrder) {
  start_daemon(0);
  std::string out;
  // The quality queue holds all four pairs offered, so that a slow (sanitizer) build drops none.
  ASSERT_EQ(start_run("pairs: 12\nrate_hz: 10\nquality: {every: 3}\nquality_queue: 4\n" + kProcessing + kLiveTier, out),
            0)
      << out;
  wait_idle();
  const msg::RunManifest m = testing_support::read_manifest(only_run_dir());
  ASSERT_EQ(m.pairs_size(), 12);
  const msg::LaneCounters* quality = lane(m.lanes(), "quality");
  ASSERT_TRUE(quality);
  EXPECT_EQ(quality->policy(), "every 3");
  EXPECT_EQ(quality->offered(), 4u);
  EXPECT_EQ(quality->processed(), 4u);
  EXPECT_EQ(quality->dropped(), 0u);
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_EQ(p.vectors().empty(), p.pair_index() % 3 != 0) << "pair " << p.pair_index();
  }
}

TEST_F(Lanes, WithoutALiveTierOneLaneRunsTheFullSettingsAsBefore) {
  start_daemon(0);
  std::string out;
  // A quality lane needs a live tier to be different from the live lane: refused, naming the key.
  EXPECT_EQ(start_run("pairs: 6\nrate_hz: 10\nquality: newest\n" + kProcessing, out), 4) << out;
  EXPECT_NE(out.find("quality"), std::string::npos) << out;
  EXPECT_NE(out.find("live: tier"), std::string::npos) << out;

  ASSERT_EQ(start_run("pairs: 6\nrate_hz: 10\n" + kProcessing, out), 0) << out;
  const msg::Status s = wait_idle();
  ASSERT_EQ(s.lanes_size(), 1);
  EXPECT_EQ(s.lanes(0).name(), "live");
  EXPECT_EQ(s.lanes(0).tier(), "full");
  const fs::path run = only_run_dir();
  const msg::RunManifest m = testing_support::read_manifest(run);
  ASSERT_EQ(m.pairs_size(), 6);
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_TRUE(p.live_vectors().empty());
    if (!p.vectors().empty()) {
      EXPECT_TRUE(fs::exists(run / p.vectors()));
    }
  }
  EXPECT_EQ(m.pairs_processed(), s.lanes(0).processed());
  EXPECT_FALSE(fs::exists(run / "vectors/live"));
  EXPECT_FALSE(fs::exists(run / "statistics-live.h5"));
}

TEST_F(Lanes, WithTheQualityLaneOffTheLiveLaneAloneRunsTheLiveTier) {
  start_daemon(0);
  std::string out;
  ASSERT_EQ(start_run("pairs: 6\nrate_hz: 10\nquality: off\n" + kProcessing + kLiveTier, out), 0) << out;
  const msg::Status s = wait_idle();
  ASSERT_EQ(s.lanes_size(), 1);
  EXPECT_EQ(s.lanes(0).tier(), "live");
  const fs::path run = only_run_dir();
  const msg::RunManifest m = testing_support::read_manifest(run);
  std::uint64_t live_files = 0;
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_TRUE(p.vectors().empty());
    live_files += !p.live_vectors().empty();
  }
  EXPECT_EQ(live_files, s.lanes(0).processed());
  EXPECT_GT(live_files, 0u);
  EXPECT_TRUE(fs::exists(run / "statistics-live.h5"));
  EXPECT_FALSE(fs::exists(run / "statistics.h5"));
}

// Frames without light and clipped frames are recorded, and named in the status and the manifest
// once per kind, from the statistics gathered while the recorder writes them.
TEST_F(Lanes, FramesWithoutLightOrClippedAreRecordedAndNamed) {
  // Frame A of every pair dark; frame B with a tenth of its pixels at the 16-bit full scale.
  ImageU16 clipped(850, 850, 100);
  for (std::size_t i = 0; i < clipped.pixels.size(); i += 10) clipped.pixels[i] = 65535;
  for (int k = 0; k < 8; k += 2) {
    io::write_tiff(scratch_ / "recordings/rec" / ("frame-" + std::to_string(k) + ".tif"), ImageU16(850, 850, 0), false);
    io::write_tiff(scratch_ / "recordings/rec" / ("frame-" + std::to_string(k + 1) + ".tif"), clipped, false);
  }
  start_daemon(0);
  std::string out;
  ASSERT_EQ(start_run("pairs: 4\nrate_hz: 10\nquality: off\n" + kProcessing + kLiveTier, out), 0) << out;
  const msg::Status s = wait_idle();
  EXPECT_EQ(s.pairs_recorded(), 4u);
  std::string warnings;
  for (const std::string& w : s.warnings()) warnings += w + "\n";
  EXPECT_NE(warnings.find("frame A all zero: no light reached the sensor"), std::string::npos) << warnings;
  EXPECT_NE(warnings.find("frame B saturated: 10.0 % of the pixels at full scale 65535"), std::string::npos)
      << warnings;
  EXPECT_NE(warnings.find(": 4 pair(s), first pair 0"), std::string::npos) << warnings;
  const msg::RunManifest m = testing_support::read_manifest(only_run_dir());
  ASSERT_EQ(m.warnings_size(), 2) << warnings;
  EXPECT_EQ(m.pairs_size(), 4);
}

// The alignment preview over real sockets: while the run acquires, frame A of the newest pair
// downsampled and refocused, on topic `preview`; `plenopiv watch --preview` prints it and writes the
// PNG (raw | refocused).
TEST_F(Lanes, TheAlignmentPreviewIsPublishedWhileAcquiring) {
  start_daemon(0);
  const fs::path png = scratch_ / "preview.png";
  ChildProcess watcher({binary("plenopiv"), "watch", "--preview", "--publish", publish_, "--count", "3", "--wait", "15",
                        "--png", png.string()},
                       scratch_ / "watch.log");
  std::this_thread::sleep_for(1500ms);  // the subscription reaches the publisher
  std::string out;
  // The run lasts until the watcher has its three previews (a sanitizer build under load makes
  // them more slowly than a fixed number of pairs would last).
  ASSERT_EQ(start_run("pairs: 0\nrate_hz: 10\npreview: {interval_s: 0.2, downsample: 5}\n" + kProcessing, out), 0)
      << out;
  const auto watched = watcher.wait(60s);
  EXPECT_EQ(client({"run", "stop"}, out), 0) << out;
  ASSERT_TRUE(watched.has_value()) << watcher.output();
  EXPECT_EQ(*watched, 0) << watcher.output();
  const std::string lines = watcher.output();
  // 850 x 850 px in 5 x 5 blocks; the replayed frames hold 100..107 counts everywhere.
  EXPECT_NE(lines.find("preview pair"), std::string::npos) << lines;
  EXPECT_NE(lines.find("raw 170x170 (1/5 of 850x850)  counts min 10"), std::string::npos) << lines;
  EXPECT_NE(lines.find("saturated 0.00 %  refocused z 0.00 mm"), std::string::npos) << lines;
  const cv::Mat picture = cv::imread(png.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(picture.empty()) << png;
  EXPECT_EQ(picture.rows, 256);  // the raw preview's 170 rows, shown at least 256 high
  EXPECT_GT(picture.cols, 256 + 8);
  const msg::Status s = wait_idle();
  EXPECT_GE(s.previews_published(), 3u);
  // One preview, then a wait of the interval: at 10 Hz and 0.2 s about one per two pairs, never one per pair.
  EXPECT_LT(s.previews_published(), s.pairs_recorded());
}

// A preview setting out of range is refused naming the key.
TEST_F(Lanes, ABadPreviewSettingIsRefusedByName) {
  start_daemon(0);
  std::string out;
  EXPECT_EQ(start_run("pairs: 3\nrate_hz: 10\npreview: {interval_s: 0.01}\n" + kProcessing, out), 4) << out;
  EXPECT_NE(out.find("preview.interval_s: must be in [0.1, 3600] s"), std::string::npos) << out;
}

}  // namespace
}  // namespace plenopiv
