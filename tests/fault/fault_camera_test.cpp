// Fault suite: plenopivd recording from Aravis's fake GigE camera (aravis://127.0.0.1, sim://
// trigger) while the camera is killed and restarted, or loses packets. What must hold: the loss
// is seen in status and manifest, the run goes on after the camera comes back, every trigger is
// a recorded pair or a listed loss, no pair mixes two triggers, and the folder reprocesses.
#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>

#include "tests/fault/fault_daemon.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/run_folder_check.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using fault::Daemon;
using testing_support::ChildProcess;

constexpr const char* kFakeCamera = "/usr/bin/arv-fake-gv-camera-0.8";
// Large packets and an explicit socket buffer (loopback loses most frames with the defaults);
// a lost camera is looked for again every 0.5 s.
const std::string kCameraUri =
    "aravis://127.0.0.1?profile=aravis-fake&packet_size=8000&socket_buffer=33554432&reconnect_s=0.5";
// The region of the fake camera's 2048 x 2048 sensor the runs read out (run.yaml camera_roi): 256 x
// 256 px, a few packets a frame, so that at 1 % packet loss most frames still arrive whole and the
// pairing of the recorded ones is tested, not only the accounting of the lost ones.
constexpr int kFramePx = 256;

// The sockets a process holds (their inodes, from /proc/<pid>/fd).
std::set<std::string> socket_inodes(pid_t pid) {
  std::set<std::string> inodes;
  std::error_code ec;
  for (const auto& fd : fs::directory_iterator("/proc/" + std::to_string(pid) + "/fd", ec)) {
    const std::string target = fs::read_symlink(fd.path(), ec).string();
    if (target.rfind("socket:[", 0) == 0) inodes.insert(target.substr(8, target.size() - 9));
  }
  return inodes;
}

// The fake camera answers once its GVCP socket (UDP 3956 on 127.0.0.1) is bound.
bool gvcp_bound(pid_t pid) {
  const std::set<std::string> inodes = socket_inodes(pid);
  std::ifstream udp("/proc/net/udp");
  std::string line;
  std::getline(udp, line);  // header
  while (std::getline(udp, line)) {
    std::istringstream fields(line);
    std::string slot, local, remote, state, queues, timer, retransmits, uid, timeout, inode;
    fields >> slot >> local >> remote >> state >> queues >> timer >> retransmits >> uid >> timeout >> inode;
    if (local == "0100007F:0F74" && inodes.count(inode)) return true;
  }
  return false;
}

// A camera file of the region the runs read out (15 x 15 lenses) and a 4 x 4 x 8 voxel volume: the
// daemon processes what it records, and the folder reprocesses, in moments.
void write_fake_camera_file(const fs::path& path) {
  std::ofstream(path) << "sensor:    {width_px: " << kFramePx << ", height_px: " << kFramePx
                      << ", pixel_pitch_mm: 0.0074}\n"
                      << "microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 15, count_y: 15, layout: rect}\n"
                         "main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}\n";
}
// `pairs` at 2 Hz (the fake camera takes a pair at most every 0.4 s: its profile), `extra` keys.
std::string run_yaml(int pairs, const std::string& extra) {
  return "pairs: " + std::to_string(pairs) + "\nrate_hz: 2\ndt_s: 0.001\n" + extra +
         "camera_roi: {width: " + std::to_string(kFramePx) + ", height: " + std::to_string(kFramePx) + "}\n" +
         "volume: {x_mm: [-0.25, 0.25], y_mm: [-0.25, 0.25], z_mm: [-0.5, 0.5], voxel_mm: 0.125}\n" +
         "reconstruction: {iterations: 1}\ncorrelation: {passes: [{window: 4, overlap_percent: 50}]}\n";
}

// Frame B has the frame id after frame A's (16-bit ids that skip 0): both came from one trigger.
std::uint64_t next_frame_id(std::uint64_t id) { return id % 65535 + 1; }

// Every trigger 0 .. triggered-1 is a recorded pair or is listed dropped with a reason, never both,
// and no pair's frames come from two triggers.
void expect_every_trigger_accounted(const msg::RunManifest& m, std::uint64_t triggered) {
  std::set<std::uint64_t> recorded, dropped;
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_TRUE(recorded.insert(p.trigger_index()).second) << "trigger " << p.trigger_index() << " recorded twice";
    EXPECT_EQ(p.frame_id_b(), next_frame_id(p.frame_id_a()))
        << "pair " << p.pair_index() << " mixes frames " << p.frame_id_a() << " and " << p.frame_id_b();
  }
  for (const msg::ManifestDrop& d : m.dropped()) {
    EXPECT_FALSE(d.reason().empty());
    EXPECT_EQ(recorded.count(d.trigger_index()), 0u)
        << "trigger " << d.trigger_index() << " recorded and listed lost (" << d.reason() << ")";
    dropped.insert(d.trigger_index());
  }
  EXPECT_EQ(recorded.size() + dropped.size(), triggered) << m.losses().DebugString();
  if (!recorded.empty()) {
    EXPECT_LT(*recorded.rbegin(), triggered);
  }
  if (!dropped.empty()) {
    EXPECT_LT(*dropped.rbegin(), triggered);
  }
}

class FaultCamera : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(kFakeCamera)) GTEST_SKIP() << kFakeCamera << " is missing (Debian package aravis-tools)";
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = info->name();  // "Name/Param" for a parametrised test
    std::replace(name.begin(), name.end(), '/', '-');
    dir_ = testing_support::temp_dir("fault-camera") / name;
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    write_fake_camera_file(dir_ / "camera.yaml");
  }

  // Starts the fake camera (losing `lost_per_thousand` of its stream packets) and waits until it answers.
  void start_fake(int lost_per_thousand = 0) {
    std::vector<std::string> argv{kFakeCamera, "-i", "127.0.0.1", "-s", "PLF" + std::to_string(::getpid())};
    if (lost_per_thousand > 0) argv.insert(argv.end(), {"-r", std::to_string(lost_per_thousand)});
    fake_ = std::make_unique<ChildProcess>(argv, dir_ / ("fake-" + std::to_string(++fake_starts_) + ".log"));
    const auto deadline = std::chrono::steady_clock::now() + 5s;
    while (!gvcp_bound(fake_->pid()) && fake_->running() && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(20ms);
    }
    ASSERT_TRUE(gvcp_bound(fake_->pid())) << "the fake camera does not answer: " << fake_->output();
  }

  void start_daemon() {
    daemon_ =
        std::make_unique<Daemon>(dir_ / "data", dir_ / "plenopivd.log", (dir_ / "camera.yaml").string(), kCameraUri);
    ASSERT_TRUE(daemon_->answers()) << daemon_->process->output();
  }

  void start_run(int pairs, const std::string& extra = "") {
    std::ofstream(dir_ / "run.yaml") << run_yaml(pairs, extra);
    std::string out;
    ASSERT_EQ(daemon_->client({"run", "start", "--config", (dir_ / "run.yaml").string()}, out), 0) << out;
  }

  // Waits for the run's end (the daemon Idle again); the last status.
  msg::Status wait_for_run_end(std::chrono::milliseconds timeout) {
    const auto s = daemon_->wait_for([](const msg::Status& s) { return s.state() == "Idle"; }, timeout);
    EXPECT_TRUE(s && s->state() == "Idle") << (s ? s->DebugString() : "no answer") << daemon_->process->output();
    return s.value_or(msg::Status{});
  }

  fs::path dir_;
  std::unique_ptr<ChildProcess> fake_;
  int fake_starts_ = 0;
  std::unique_ptr<Daemon> daemon_;
};

// plenopivd reconstructs with its camera file: a run whose frames would be of another size, the
// fake camera's whole 2048² sensor or a region of another size, is refused at start naming both
// sizes, and no run folder is made.
TEST_F(FaultCamera, FramesOfAnotherSizeThanTheCameraFileAreRefusedAtStart) {
  ASSERT_NO_FATAL_FAILURE(start_fake());
  ASSERT_NO_FATAL_FAILURE(start_daemon());
  const std::string file = (dir_ / "camera.yaml").string();
  for (const auto& [roi, culprit] :
       {std::pair<std::string, std::string>{"", "camera_uri " + kCameraUri + ": a sensor of 2048 x 2048 px"},
        {"camera_roi: {width: 128, height: 256}\n", "camera_roi: a region of 128 x 256 px"}}) {
    std::ofstream(dir_ / "run.yaml") << "pairs: 2\nrate_hz: 2\ndt_s: 0.001\n" + roi +
                                            "volume: {x_mm: [-0.25, 0.25], y_mm: [-0.25, 0.25], z_mm: [-0.5, 0.5], "
                                            "voxel_mm: 0.125}\ncorrelation: {passes: [{window: 4}]}\n";
    std::string out;
    EXPECT_EQ(daemon_->client({"run", "start", "--config", (dir_ / "run.yaml").string()}, out), 4) << out;
    EXPECT_NE(out.find(culprit + " does not match camera_file " + file + ", whose sensor is 256 x 256 px"),
              std::string::npos)
        << out;
  }
  EXPECT_TRUE(!fs::exists(dir_ / "data") || fs::is_empty(dir_ / "data"));
}

// The camera killed (SIGKILL) a few pairs into a run (until stopped) and started again once the
// daemon has seen it gone: status says the camera is lost while it is, the run goes on when it is
// back, counts the reconnect and the triggers lost meanwhile, and records pairs after it; stopped,
// every trigger it made is a recorded pair or listed lost, and the folder is consistent and
// reprocessable; the daemon answers throughout and takes the next run.
TEST_F(FaultCamera, AKilledCameraIsCountedLostAndTheRunGoesOnAfterItComesBack) {
  start_fake();
  start_daemon();
  start_run(0);
  auto s = daemon_->wait_for([](const msg::Status& s) { return s.pairs_recorded() >= 3; }, 15s);
  ASSERT_TRUE(s && s->pairs_recorded() >= 3) << (s ? s->DebugString() : "no answer");
  fake_->signal(SIGKILL);
  ASSERT_TRUE(fake_->wait(2s).has_value());
  const auto killed = std::chrono::steady_clock::now();

  // Aravis gives up on a camera that stopped answering after its GVCP retries (0.5 s each, five
  // per register): seconds.
  s = daemon_->wait_for([](const msg::Status& s) { return s.message().find("camera lost") != std::string::npos; }, 25s);
  ASSERT_TRUE(s && s->message().find("camera lost") != std::string::npos)
      << "the loss was not seen: " << (s ? s->DebugString() : "no answer");
  const double seen_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - killed).count();
  EXPECT_EQ(s->state(), "Acquiring");
  const std::uint64_t recorded_before = s->pairs_recorded();

  start_fake();
  s = daemon_->wait_for([](const msg::Status& s) { return s.losses().camera_reconnects() >= 1; }, 10s);
  ASSERT_TRUE(s && s->losses().camera_reconnects() == 1) << (s ? s->DebugString() : "no answer");
  EXPECT_EQ(s->state(), "Acquiring");
  EXPECT_EQ(s->message().find("camera lost"), std::string::npos) << s->message();
  s = daemon_->wait_for([&](const msg::Status& s) { return s.pairs_recorded() >= recorded_before + 2; }, 10s);
  ASSERT_TRUE(s && s->pairs_recorded() >= recorded_before + 2)
      << "no pairs after the camera came back: " << (s ? s->DebugString() : "no answer");
  std::string out;
  ASSERT_EQ(daemon_->client({"run", "stop"}, out), 0) << out;
  const msg::Status end = wait_for_run_end(15s);
  std::printf("camera lost seen %.1f s after the kill; %llu pairs recorded, %llu triggers lost with the camera\n",
              seen_s, static_cast<unsigned long long>(end.pairs_recorded()),
              static_cast<unsigned long long>(end.losses().camera_lost()));
  EXPECT_EQ(end.losses().camera_reconnects(), 1u);
  EXPECT_GE(end.losses().camera_lost(), 1u);

  const std::vector<fs::path> runs = testing_support::run_folders(dir_ / "data");
  ASSERT_EQ(runs.size(), 1u);
  const msg::RunManifest m = testing_support::expect_consistent_and_reprocessable(runs[0], kFramePx, kFramePx);
  EXPECT_EQ(m.state(), "stopped");
  EXPECT_EQ(m.losses().camera_lost(), end.losses().camera_lost());
  EXPECT_EQ(m.losses().camera_reconnects(), 1u);
  // The run made triggers 0 .. its last: each one recorded or listed lost.
  std::uint64_t last = 0;
  for (const msg::ManifestPair& p : m.pairs()) last = std::max(last, p.trigger_index());
  for (const msg::ManifestDrop& d : m.dropped()) last = std::max(last, d.trigger_index());
  expect_every_trigger_accounted(m, last + 1);
  std::size_t camera_lost_listed = 0;
  for (const msg::ManifestDrop& d : m.dropped()) camera_lost_listed += d.reason() == "camera lost";
  EXPECT_EQ(camera_lost_listed, m.losses().camera_lost());

  // The daemon takes the next run on the camera that came back, and accounts for all of it (the
  // fake camera, paired by host arrival time, loses a pair now and then on a loaded machine).
  start_run(4);
  const msg::Status next_end = wait_for_run_end(15s);
  const std::vector<fs::path> both = testing_support::run_folders(dir_ / "data");
  ASSERT_EQ(both.size(), 2u);
  const msg::RunManifest next = testing_support::read_manifest(both[1]);
  std::string dropped;  // why, for a failure's message
  for (const msg::ManifestDrop& d : next.dropped())
    dropped += " trigger " + std::to_string(d.trigger_index()) + ": " + d.reason() + ";";
  EXPECT_GE(next_end.pairs_recorded(), 1u) << "dropped:" << dropped << "\n"
                                           << next_end.DebugString() << "\n"
                                           << daemon_->process->output();
  EXPECT_EQ(next.state(), "complete");
  expect_every_trigger_accounted(next, 4);
  daemon_->process->signal(SIGTERM);
  EXPECT_TRUE(daemon_->process->wait(10s).has_value());
}

// A camera that stays away longer than the run's camera_outage_s fails the run, naming the camera
// and the loss; the pairs before it stay in a consistent, reprocessable folder, and the daemon
// answers and refuses nothing it should not.
TEST_F(FaultCamera, ACameraThatDoesNotComeBackFailsTheRunNamingIt) {
  start_fake();
  start_daemon();
  start_run(0, "camera_outage_s: 1\n");
  auto s = daemon_->wait_for([](const msg::Status& s) { return s.pairs_recorded() >= 2; }, 15s);
  ASSERT_TRUE(s && s->pairs_recorded() >= 2) << (s ? s->DebugString() : "no answer");
  fake_->signal(SIGKILL);
  ASSERT_TRUE(fake_->wait(2s).has_value());
  const auto killed = std::chrono::steady_clock::now();
  s = daemon_->wait_for([](const msg::Status& s) { return s.state() == "Error"; }, 25s);
  ASSERT_TRUE(s && s->state() == "Error") << (s ? s->DebugString() : "no answer");
  std::printf("the run failed %.1f s after the camera was killed\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - killed).count());
  EXPECT_NE(s->message().find("camera " + kCameraUri + " lost for more than 1 s"), std::string::npos) << s->message();
  EXPECT_NE(s->message().find("control lost"), std::string::npos) << s->message();

  const std::vector<fs::path> runs = testing_support::run_folders(dir_ / "data");
  ASSERT_EQ(runs.size(), 1u);
  const msg::RunManifest m = testing_support::expect_consistent_and_reprocessable(runs[0], kFramePx, kFramePx);
  EXPECT_EQ(m.state().rfind("failed: ", 0), 0u) << m.state();
  EXPECT_NE(m.state().find("lost for more than 1 s"), std::string::npos) << m.state();
  EXPECT_GE(m.pairs_size(), 2);
  EXPECT_GE(m.losses().camera_lost(), 1u);
  EXPECT_EQ(m.losses().camera_reconnects(), 0u);
  EXPECT_TRUE(daemon_->answers());
  daemon_->process->signal(SIGTERM);
  EXPECT_TRUE(daemon_->process->wait(10s).has_value());
}

// The fake camera losing `-r` packets per thousand (Aravis 0.8's fake camera ignores resend
// requests): frames arrive incomplete, their pairs are dropped and listed, every trigger is
// accounted for in the manifest and every frame in status, and no recorded pair mixes frames of
// two triggers.
class FaultCameraPacketLoss : public FaultCamera, public ::testing::WithParamInterface<int> {};

TEST_P(FaultCameraPacketLoss, EveryTriggerIsRecordedOrListedLostAndNoPairIsMismatched) {
  // At 1 % about half the frames of a 256 x 256 region arrive incomplete: 48 frames have both kinds,
  // and the pairing of the recorded ones is checked.
  constexpr int pairs = 24;
  start_fake(GetParam());
  start_daemon();
  start_run(pairs);
  const msg::Status end = wait_for_run_end(pairs * 1s + 15s);
  const std::vector<fs::path> runs = testing_support::run_folders(dir_ / "data");
  ASSERT_EQ(runs.size(), 1u);
  const msg::RunManifest m = testing_support::expect_consistent_and_reprocessable(runs[0], kFramePx, kFramePx);
  std::printf("%d per thousand packets lost: %d pairs recorded, %d triggers listed lost; losses %s\n", GetParam(),
              m.pairs_size(), m.dropped_size(), m.losses().ShortDebugString().c_str());
  EXPECT_EQ(m.state(), "complete");
  expect_every_trigger_accounted(m, pairs);
  EXPECT_GT(m.losses().frames_discarded(), 0u) << "no frame came incomplete: -r had no effect";
  if (GetParam() == 10) {
    EXPECT_GE(m.pairs_size(), pairs / 6) << "at 1 % packet loss about half the pairs arrive whole";
  }
  EXPECT_EQ(m.losses().camera_lost(), 0u);
  EXPECT_EQ(end.pairs_recorded(), std::uint64_t(m.pairs_size()));
  EXPECT_EQ(end.frames_lost(), m.frames_lost());
  EXPECT_EQ(2 * end.pairs_recorded() + end.frames_lost(), 2u * pairs) << end.losses().DebugString();
  daemon_->process->signal(SIGTERM);
  EXPECT_TRUE(daemon_->process->wait(10s).has_value());
}

std::string rate_name(const ::testing::TestParamInfo<int>& info) { return std::to_string(info.param) + "PerThousand"; }
INSTANTIATE_TEST_SUITE_P(OneAndFivePercent, FaultCameraPacketLoss, ::testing::Values(10, 50), rate_name);

}  // namespace
}  // namespace plenopiv
