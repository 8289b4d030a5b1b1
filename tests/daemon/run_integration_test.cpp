// Runs end to end: plenopivd (test camera) as a child process, driven by the thin client, watched
// by subscribers; illegal and invalid requests refused while it keeps serving; SIGTERM mid-run.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <fstream>
#include <iomanip>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

#include "clients/cli/control_client.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/daemon_status.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using testing_support::binary;
using testing_support::ChildProcess;

const std::string kRun =
    "rate_hz: 10\ndt_s: 0.001\n"
    "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 2], voxel_mm: 0.5}\n"
    "correlation: {passes: [{window: 4, overlap_percent: 50}]}\n";

class DaemonRuns : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    scratch_ = testing_support::temp_dir("daemon-runs") / name;
    fs::remove_all(scratch_);
    fs::create_directories(scratch_);
    start_daemon();
  }

  // A fresh plenopivd on the same data directory (after the last one ended).
  void restart_daemon() {
    daemon_.reset();
    start_daemon();
  }

  void start_daemon() {
    control_ = testing_support::ipc_endpoint("control");
    publish_ = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
    daemon_ = std::make_unique<ChildProcess>(
        std::vector<std::string>{binary("plenopivd-testcam"), "--control", control_, "--publish", publish_, "--camera",
                                 "test://", "--data-dir", (scratch_ / "data").string(), "--simulation", "--camera-file",
                                 std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml"},
        scratch_ / "plenopivd.log");
    for (int i = 0; i < 100; ++i) {
      if (status_or_null()) return;
      ASSERT_TRUE(daemon_->running()) << daemon_->output();
    }
    FAIL() << "plenopivd did not answer: " << daemon_->output();
  }

  std::optional<msg::Status> status_or_null() { return testing_support::probe_status(control_); }

  // The daemon's status, asked again while a probe times out (a sanitizer build answers slowly); a
  // daemon that never answers is a test failure and gives an empty status.
  msg::Status status() {
    for (int i = 0; i < 40; ++i) {
      if (const auto s = status_or_null()) return *s;
    }
    ADD_FAILURE() << "plenopivd did not answer a status request: " << daemon_->output();
    return {};
  }

  void wait_for_state(const std::string& state) {
    for (int i = 0; i < 300; ++i) {
      const auto s = status_or_null();
      if (s && s->state() == state) return;
      std::this_thread::sleep_for(50ms);
    }
    FAIL() << "plenopivd never reached " << state << ": " << daemon_->output();
  }

  int client(const std::vector<std::string>& args, std::string& out) {
    std::vector<std::string> argv{binary("plenopiv"), "--endpoint", control_};
    argv.insert(argv.end(), args.begin(), args.end());
    return testing_support::run_command(argv, out);
  }

  fs::path write_config(const std::string& text) {
    const fs::path path = scratch_ / "run.yaml";
    std::ofstream(path) << text;
    return path;
  }

  msg::RunManifest manifest(const fs::path& run_dir) { return testing_support::read_manifest(run_dir); }

  fs::path only_run_dir() { return testing_support::only_run_folder(scratch_ / "data"); }

  fs::path scratch_;
  std::string control_, publish_;
  std::unique_ptr<ChildProcess> daemon_;
};

TEST_F(DaemonRuns, RunOfNPairsReachesSubscribersAndTheRunFolder) {
  constexpr int n = 6;
  // A C++ subscriber: the thin client's `watch`, started before the run (PUB/SUB joins late).
  ChildProcess watcher(
      {binary("plenopiv"), "watch", "--publish", publish_, "--count", std::to_string(n), "--wait", "20"},
      scratch_ / "watch.log");
  // The Python subscriber (the installed plenopiv package), saving vector files and plotting.
  const fs::path saved_dir = scratch_ / "fields", png = scratch_ / "view.png";
  ChildProcess python({PLENOPIV_PACKAGE_PYTHON, "-m", "plenopiv.subscribe", "--publish", publish_, "--count",
                       std::to_string(n), "--wait", "20", "--save", saved_dir.string(), "--plot", png.string()},
                      scratch_ / "python.log");
  // The Python subscriber says when it has subscribed (its imports take seconds on a loaded machine).
  for (int i = 0; i < 600 && python.output().find("subscribed to") == std::string::npos; ++i)
    std::this_thread::sleep_for(100ms);
  ASSERT_NE(python.output().find("subscribed to"), std::string::npos) << python.output();
  std::this_thread::sleep_for(1500ms);  // both subscriptions reach the publisher

  std::string out;
  // This test is about delivery, not pace: every pair may be in flight at once, at 1 Hz. The live
  // lane takes the newest pair waiting and drops the older ones, so a pair is skipped whenever the
  // next one is recorded before the lane took it: under a sanitizer's slowdown, at 10 Hz, and at
  // 2 Hz when the first pair's recording (the run folder's first files) held both pairs back.
  const std::string all = std::to_string(n);
  const std::string config = "rate_hz: 1\n" + kRun.substr(kRun.find("dt_s")) + "max_pairs_in_flight: " + all + "\n";
  ASSERT_EQ(client({"run", "start", "--config", write_config(config).string(), "--pairs", all}, out), 0) << out;
  EXPECT_NE(out.find("started"), std::string::npos) << out;

  const auto watched = watcher.wait(30s);
  ASSERT_TRUE(watched.has_value()) << "watch did not see " << n << " fields: " << watcher.output();
  EXPECT_EQ(*watched, 0) << watcher.output();
  // Consecutive pair indices, each field's u = its pair index (the test processing stage).
  const std::string lines = watcher.output();
  for (int i = 0; i < n; ++i) {
    std::ostringstream expect;
    expect << "pair " << std::setw(6) << i << "  mean " << std::fixed << std::setprecision(4) << double(i) << " m/s";
    EXPECT_NE(lines.find(expect.str()), std::string::npos) << expect.str() << "\n" << lines;
  }
  EXPECT_NE(lines.find("valid 75.0 %"), std::string::npos) << lines;
  // The trigger measured each pair's laser pulses: the header carries pulse 1 -> published.
  EXPECT_NE(lines.find(" from laser "), std::string::npos) << lines;

  const auto py = python.wait(30s);
  ASSERT_TRUE(py.has_value()) << "the Python subscriber did not see " << n << " fields";
  EXPECT_EQ(*py, 0) << python.output();
  EXPECT_NE(python.output().find("pair      5  mean 5.0000 m/s"), std::string::npos) << python.output();
  EXPECT_TRUE(fs::exists(png));
  wait_for_state("Idle");
  const fs::path run = only_run_dir();
  const msg::RunManifest m = manifest(run);
  EXPECT_EQ(m.state(), "complete");
  ASSERT_EQ(m.pairs_size(), n);
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(m.pairs(i).pair_index(), std::uint64_t(i));
    EXPECT_TRUE(fs::exists(run / m.pairs(i).frame_a()));
    EXPECT_TRUE(fs::exists(run / m.pairs(i).frame_b()));
    EXPECT_EQ(m.pairs(i).vectors(), "vectors/" + fs::path(m.pairs(i).frame_a()).stem().string().substr(0, 11) + ".h5");
  }
  EXPECT_TRUE(fs::exists(run / "statistics.h5"));
  EXPECT_TRUE(fs::exists(run / "run.yaml"));

  // The saved fields, read back with plenopiv.open: u = pair index at every node, on the axes of the
  // run folder's vector files, with the values the daemon recorded.
  std::string saved;
  ASSERT_EQ(testing_support::run_command(
                {PLENOPIV_PACKAGE_PYTHON, "-c",
                 "import sys, plenopiv; s = plenopiv.open(sys.argv[1]); r = plenopiv.open(sys.argv[2]); "
                 "print(s.sizes['pair'], [float(s.u.sel(pair=i)[1, 2, 3]) for i in s.pair.values], s.u.shape, "
                 "s.u.dims, s.u.attrs['units'], "
                 "'same-as-recorded' if (s.u == r.u).all() and (s.x == r.x).all() else 'differs')",
                 saved_dir.string(), run.string()},
                saved),
            0)
      << saved;
  EXPECT_NE(saved.find("6 [0.0, 1.0, 2.0, 3.0, 4.0, 5.0] (6, 2, 3, 4) ('pair', 'z', 'y', 'x') m/s"), std::string::npos)
      << saved;
  EXPECT_NE(saved.find("same-as-recorded"), std::string::npos) << saved;

  ASSERT_EQ(client({"status"}, out), 0) << out;
  EXPECT_NE(out.find("recorded " + std::to_string(n)), std::string::npos) << out;
}

TEST_F(DaemonRuns, IllegalAndInvalidRequestsAreRefusedAndTheDaemonServesOn) {
  std::string out;
  EXPECT_EQ(client({"run", "stop"}, out), 4) << out;
  EXPECT_NE(out.find("WRONG_STATE: no run to stop"), std::string::npos) << out;

  EXPECT_EQ(client({"run", "start", "--config", write_config(kRun + "pairz: 3\n").string()}, out), 4);
  EXPECT_NE(out.find("INVALID"), std::string::npos) << out;
  EXPECT_NE(out.find("pairz: unknown key"), std::string::npos) << out;

  EXPECT_EQ(client({"run", "start", "--config", write_config(kRun + "camera_uri: nosuch://\n").string()}, out), 4);
  EXPECT_NE(out.find("nosuch"), std::string::npos) << out;
  EXPECT_EQ(status().state(), "Idle");  // the refused start changed nothing

  ASSERT_EQ(client({"run", "start", "--config", write_config(kRun).string()}, out), 0) << out;
  EXPECT_EQ(client({"run", "start", "--config", write_config(kRun).string()}, out), 4);
  EXPECT_NE(out.find("WRONG_STATE: cannot start a run"), std::string::npos) << out;
  EXPECT_EQ(client({"capture-calibration"}, out), 4);
  EXPECT_NE(out.find("WRONG_STATE: cannot take calibration images"), std::string::npos) << out;

  ASSERT_EQ(client({"run", "stop"}, out), 0) << out;
  wait_for_state("Idle");
  EXPECT_EQ(manifest(only_run_dir()).state(), "stopped");

  ASSERT_EQ(client({"capture-calibration", "--frames", "2"}, out), 0) << out;
  EXPECT_NE(out.find("2 calibration images in"), std::string::npos) << out;
  // A repetition rate that would overflow the trigger's nanosecond clock is refused, naming it.
  const std::string slow = "rate_hz: 1.0e-12\n" + kRun.substr(kRun.find("dt_s"));
  EXPECT_EQ(client({"run", "start", "--config", write_config(slow).string()}, out), 4);
  EXPECT_NE(out.find("INVALID"), std::string::npos) << out;
  EXPECT_NE(out.find("below one pair per 3600 s"), std::string::npos) << out;
  EXPECT_TRUE(daemon_->running());
}

// A camera whose render thread fails ends the run as failed, with the reason, and the daemon serves
// on: a new run can start.
TEST_F(DaemonRuns, ACameraThatFailsFailsTheRunNotTheDaemon) {
  std::string out;
  ASSERT_EQ(
      client({"run", "start", "--config",
              write_config(kRun + "camera_uri: \"sim://?rays=200&ppm=0.02&fail_after=1\"\n").string(), "--pairs", "5"},
             out),
      0)
      << out;
  for (int i = 0; i < 200; ++i) {
    const auto s = status_or_null();
    if (s && s->state() == "Error") break;
    std::this_thread::sleep_for(50ms);
  }
  const auto s = status_or_null();
  ASSERT_TRUE(s);
  EXPECT_EQ(s->state(), "Error");
  EXPECT_NE(s->message().find("simulated render fault"), std::string::npos) << s->message();
  EXPECT_EQ(manifest(only_run_dir()).state().rfind("failed: camera sim://", 0), 0u) << manifest(only_run_dir()).state();
  EXPECT_TRUE(daemon_->running());
  ASSERT_EQ(client({"run", "start", "--config", write_config(kRun).string(), "--pairs", "2"}, out), 0) << out;
}

// SIGKILL leaves the folder "recording"; the next daemon marks it "interrupted", and it still lists
// exactly the pairs on disk.
TEST_F(DaemonRuns, AFolderLeftRecordingByAKilledDaemonIsMarkedInterrupted) {
  std::string out;
  ASSERT_EQ(client({"run", "start", "--config", write_config(kRun).string()}, out), 0) << out;
  wait_for_state("Acquiring");
  for (int i = 0; i < 100 && status().pairs_recorded() < 3; ++i) std::this_thread::sleep_for(50ms);
  daemon_->signal(SIGKILL);
  ASSERT_TRUE(daemon_->wait(5s).has_value());
  const fs::path run = only_run_dir();
  EXPECT_EQ(manifest(run).state(), "recording");
  restart_daemon();
  const msg::RunManifest m = manifest(run);
  EXPECT_EQ(m.state(), "interrupted");
  ASSERT_GT(m.pairs_size(), 0);
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_TRUE(fs::exists(run / p.frame_a())) << p.frame_a();
    EXPECT_TRUE(fs::exists(run / p.frame_b())) << p.frame_b();
  }
  EXPECT_NE(daemon_->output().find("marked interrupted"), std::string::npos) << daemon_->output();
}

// Frames that reach the camera driver but no recorded pair are reported: a frame A whose B never
// came was discarded by the pairer and used to be left out of the status's "frames lost".
TEST_F(DaemonRuns, UnpairedFramesCountAsLost) {
  std::string out;
  const std::string camera = "sim://?rays=200&ppm=0.02&drop_every=2";
  ASSERT_EQ(client({"run", "start", "--config", write_config(kRun + "camera_uri: \"" + camera + "\"\n").string(),
                    "--pairs", "4"},
                   out),
            0)
      << out;
  std::this_thread::sleep_for(500ms);
  wait_for_state("Idle");
  const auto s = status_or_null();
  ASSERT_TRUE(s);
  // Triggers 1 and 3 lose frame B: B1 is a gap in the ids (lost), A1 and A3 wait for partners that
  // never come (discarded), and B3, the run's last frame, never arrives (counted at the run's end
  // against the triggers made); pairs 0 and 2 are recorded.
  EXPECT_EQ(s->pairs_recorded(), 2u);
  EXPECT_EQ(s->frames_lost(), 4u);
  // ... and the log says so at the run's end.
  EXPECT_NE(daemon_->output().find("2 pairs recorded, 2 processed, 0 skipped, 4 frames lost"), std::string::npos)
      << daemon_->output();
  // The manifest names the triggers with no pair and why, and counts every loss.
  const msg::RunManifest m = manifest(only_run_dir());
  ASSERT_EQ(m.dropped_size(), 2) << m.DebugString();
  EXPECT_EQ(m.dropped(0).trigger_index(), 1u);
  EXPECT_EQ(m.dropped(1).trigger_index(), 3u);
  for (const msg::ManifestDrop& d : m.dropped()) EXPECT_EQ(d.reason(), "unpaired frame");
  EXPECT_EQ(m.frames_lost(), 4u);
  EXPECT_EQ(m.losses().frames_never_arrived(), 2u);
  EXPECT_EQ(m.losses().frames_discarded(), 2u);
}

TEST_F(DaemonRuns, SigtermMidRunDrainsAndLeavesTheFolderConsistent) {
  std::string out;
  ASSERT_EQ(client({"run", "start", "--config", write_config(kRun).string()}, out), 0) << out;
  wait_for_state("Acquiring");
  std::this_thread::sleep_for(600ms);
  daemon_->signal(SIGTERM);
  const auto status = daemon_->wait(10s);
  ASSERT_TRUE(status.has_value()) << "plenopivd did not stop on SIGTERM";
  EXPECT_EQ(*status, 0) << daemon_->output();

  const fs::path run = only_run_dir();
  const msg::RunManifest m = manifest(run);
  EXPECT_EQ(m.state(), "stopped");
  EXPECT_GT(m.pairs_size(), 0);
  std::set<std::string> listed;
  for (const msg::ManifestPair& p : m.pairs()) {
    listed.insert(p.frame_a());
    listed.insert(p.frame_b());
    if (!p.vectors().empty()) listed.insert(p.vectors());
  }
  std::set<std::string> on_disk;
  for (const char* sub : {"frames", "vectors"}) {
    for (const auto& e : fs::directory_iterator(run / sub)) {
      on_disk.insert(std::string(sub) + "/" + e.path().filename().string());
    }
  }
  EXPECT_EQ(listed, on_disk);  // nothing half-written, nothing unlisted
}

}  // namespace
}  // namespace plenopiv

namespace plenopiv {
namespace {

// A stand-in for systemd's notify socket: collects what plenopivd sends (READY, STATUS, WATCHDOG)
// as it arrives, as systemd does. A datagram socket queues only net.unix.max_dgram_qlen (often 10)
// unread messages before the sender blocks, so a reader that waited for the test would stall the
// daemon's control loop on a slow machine.
class NotifySocket {
 public:
  using Message = std::pair<std::chrono::steady_clock::time_point, std::string>;

  explicit NotifySocket(const fs::path& path) : path_(path) {
    fs::remove(path);
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      throw std::runtime_error("cannot bind " + path.string());
    }
    const timeval poll{0, 20000};  // the reader looks at stop_ every 20 ms
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &poll, sizeof poll);
    reader_ = std::thread([this] {
      char buffer[4096];
      while (!stop_) {
        const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
        if (n <= 0) continue;
        std::lock_guard lock(mutex_);
        received_.emplace_back(std::chrono::steady_clock::now(), std::string(buffer, std::size_t(n)));
      }
    });
  }
  ~NotifySocket() {
    stop_ = true;
    reader_.join();
    ::close(fd_);
  }
  // Every datagram received since the last drain, with the time it arrived.
  std::vector<Message> drain() {
    std::lock_guard lock(mutex_);
    return std::exchange(received_, {});
  }

 private:
  fs::path path_;
  int fd_ = -1;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::vector<Message> received_;
  std::thread reader_;
};

TEST(DaemonNotify, ReadyStatusAndAWatchdogThatStopsWhenTheRunStalls) {
  const fs::path scratch = testing_support::temp_dir("daemon-notify");
  NotifySocket notify(scratch / "notify.sock");
  const std::string control = testing_support::ipc_endpoint("control");
  const std::string publish = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  ::setenv("NOTIFY_SOCKET", (scratch / "notify.sock").c_str(), 1);
  ::setenv("WATCHDOG_USEC", "1000000", 1);  // 1 s: pings needed every 0.5 s
  ChildProcess daemon({binary("plenopivd-testcam"), "--control", control, "--publish", publish, "--camera", "test://",
                       "--data-dir", (scratch / "data").string()},
                      scratch / "plenopivd.log");
  ::unsetenv("NOTIFY_SOCKET");
  ::unsetenv("WATCHDOG_USEC");

  std::vector<std::string> messages;
  for (int i = 0; i < 100 && messages.empty(); ++i) {
    std::this_thread::sleep_for(50ms);
    for (auto& [t, m] : notify.drain()) messages.push_back(m);
  }
  ASSERT_FALSE(messages.empty()) << daemon.output();
  EXPECT_EQ(messages[0], "READY=1\nSTATUS=Idle");
  // Pings come every half interval (0.5 s); a loaded sanitizer build may send them late, so wait up to 5 s.
  int pings = 0;
  for (int i = 0; i < 50 && pings < 2; ++i) {
    std::this_thread::sleep_for(100ms);
    for (auto& [t, m] : notify.drain()) pings += m == "WATCHDOG=1";
  }
  EXPECT_GE(pings, 2) << "no watchdog pings while idle";

  // A run whose camera loses every frame makes no progress: the pings stop.
  std::string lost;
  for (int i = 0; i < 400; ++i) lost += (i ? "," : "") + std::to_string(i);
  const fs::path config = scratch / "stalled.yaml";
  std::ofstream(config) << kRun << "camera_uri: test://?lose=" << lost << "\n";
  std::string out;
  ASSERT_EQ(testing_support::run_command(
                {binary("plenopiv"), "--endpoint", control, "run", "start", "--config", config.string()}, out),
            0)
      << out;
  const auto started = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(1500ms);
  const std::vector<NotifySocket::Message> received = notify.drain();
  bool saw_acquiring = false;
  int late_pings = 0;
  for (auto& [t, m] : received) {
    saw_acquiring = saw_acquiring || m.rfind("STATUS=Acquiring run ", 0) == 0;
    // Half the watchdog time after the start (plus a poll period), no more pings.
    if (m == "WATCHDOG=1" && t - started > 700ms) ++late_pings;
  }
  EXPECT_TRUE(saw_acquiring);
  EXPECT_EQ(late_pings, 0) << "the watchdog was fed although no pair arrived";

  ASSERT_EQ(testing_support::run_command({binary("plenopiv"), "--endpoint", control, "run", "stop"}, out), 0) << out;
  daemon.signal(SIGTERM);
  ASSERT_TRUE(daemon.wait(10s).has_value());
  bool stopping = false;
  for (auto& [t, m] : notify.drain()) stopping = stopping || m.rfind("STOPPING=1", 0) == 0;
  EXPECT_TRUE(stopping);
}

}  // namespace
}  // namespace plenopiv
