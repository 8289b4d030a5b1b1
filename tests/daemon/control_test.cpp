// plenopivd as a real child process on real ZeroMQ sockets: replies, bad messages, timeouts, SIGTERM.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <thread>
#include <zmq.hpp>

#include "clients/cli/control_client.hpp"
#include "core/base/isa.hpp"
#include "proto/curve.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/daemon_status.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/shallow_spec.hpp"
#include "tests/support/temp_dir.hpp"
#include "tests/support/tmpfs.hpp"

namespace plenopiv {
namespace {

using namespace std::chrono_literals;
using testing_support::ChildProcess;

// plenopivd's command line on the simulated small camera (`camera`: its sim:// URI), answering on
// `control`, its runs in `data_dir`.
std::vector<std::string> sim_daemon(const std::string& control, const std::filesystem::path& data_dir,
                                    const std::string& camera) {
  return {testing_support::binary("plenopivd"),
          "--simulation",
          "--camera-file",
          std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml",
          "--camera",
          camera,
          "--control",
          control,
          "--publish",
          "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port()),
          "--data-dir",
          data_dir.string()};
}

// A fresh, empty folder `name` in this test process's `area` (testing_support::temp_dir).
std::filesystem::path fresh_dir(const std::string& area, const std::string& name) {
  const std::filesystem::path dir = testing_support::temp_dir(area) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// Whether `daemon` answers a status request on `control` (up to 100 tries) before it ends.
bool answers(ChildProcess& daemon, const std::string& control) {
  for (int i = 0; i < 100; ++i) {
    if (testing_support::probe_status(control)) return true;
    if (!daemon.running()) return false;
  }
  return false;
}

class Daemon : public ::testing::Test {
 protected:
  void SetUp() override {
    control_ = testing_support::ipc_endpoint("control");
    publish_ = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
    daemon_ = std::make_unique<ChildProcess>(
        std::vector<std::string>{testing_support::binary("plenopivd"), "--control", control_, "--publish", publish_,
                                 "--log-level", "info"},
        std::filesystem::temp_directory_path() / "plenopiv-test" /
            (std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + ".log"));
    // Wait for the control socket to answer.
    for (int i = 0; i < 100; ++i) {
      if (testing_support::probe_status(control_)) return;
      ASSERT_TRUE(daemon_->running()) << daemon_->output();
    }
    FAIL() << "plenopivd did not answer: " << daemon_->output();
  }

  // Sends raw bytes on a REQ socket and returns the parsed reply.
  msg::Reply raw_call(const std::string& bytes) {
    zmq::context_t ctx;
    zmq::socket_t req(ctx, zmq::socket_type::req);
    req.set(zmq::sockopt::linger, 0);
    req.set(zmq::sockopt::rcvtimeo, 3000);
    req.connect(control_);
    req.send(zmq::buffer(bytes), zmq::send_flags::none);
    zmq::message_t answer;
    EXPECT_TRUE(req.recv(answer, zmq::recv_flags::none)) << "no reply to a raw message";
    msg::Reply reply;
    EXPECT_TRUE(reply.ParseFromArray(answer.data(), int(answer.size())));
    return reply;
  }

  std::string control_, publish_;
  std::unique_ptr<ChildProcess> daemon_;
};

TEST_F(Daemon, AnswersStatusAndStopsCleanlyOnSigterm) {
  client::ControlClient client(control_);
  msg::Request r;
  r.mutable_status();
  const msg::Reply reply = client.call(r);
  ASSERT_TRUE(reply.has_status());
  EXPECT_EQ(reply.status().state(), "Idle");
  EXPECT_EQ(reply.id(), 1u);
  // The kernels' build: the CPU's best, unless the environment the daemon inherited names one.
  const char* named = std::getenv("PLENOPIV_ISA");
  const std::string kernels = named && *named ? named : isa_name(best_isa());
  EXPECT_EQ(reply.status().kernels(), kernels);
  EXPECT_NE(daemon_->output().find("kernels: the " + kernels + " build"), std::string::npos) << daemon_->output();

  daemon_->signal(SIGTERM);
  const auto status = daemon_->wait(5s);
  ASSERT_TRUE(status.has_value()) << "plenopivd did not stop on SIGTERM";
  EXPECT_EQ(*status, 0) << daemon_->output();
  EXPECT_NE(daemon_->output().find("plenopivd stopping"), std::string::npos);
}

TEST_F(Daemon, MalformedAndEmptyRequestsGetErrorRepliesAndTheDaemonGoesOn) {
  const msg::Reply garbage = raw_call(std::string("\xff\xff\xff not protobuf", 17));
  ASSERT_TRUE(garbage.has_error());
  EXPECT_EQ(garbage.error().code(), msg::Error::MALFORMED);
  EXPECT_NE(garbage.error().message().find("not a plenopiv.msg.Request"), std::string::npos);

  const msg::Reply empty = raw_call(msg::Request().SerializeAsString());
  ASSERT_TRUE(empty.has_error());
  EXPECT_EQ(empty.error().code(), msg::Error::MALFORMED);
  EXPECT_NE(empty.error().message().find("names no operation"), std::string::npos);

  client::ControlClient client(control_);
  msg::Request r;
  r.mutable_status();
  EXPECT_TRUE(client.call(r).has_status());
  EXPECT_TRUE(daemon_->running());
}

// A run config whose key holds a NUL: the YAML parser reads it as bytes that are not UTF-8, and the
// error that quotes the key still makes a reply a client can read (the fuzzer's find).
TEST_F(Daemon, AnErrorQuotingBytesThatAreNotUtf8IsAReadableReply) {
  msg::Request r;
  r.set_id(6);
  r.mutable_start_run()->set_config_yaml(std::string(
      "rate_hz: 10\nvolume: {x_mm: [-0.25, 0.25], y_mm: [-0.25, 0.25], z_mm: [-0.5, 0.5], v\x08\x02\"\0_mm: "
      "0.125}\n",
      99));
  const msg::Reply reply = raw_call(r.SerializeAsString());
  ASSERT_TRUE(reply.has_error()) << reply.ShortDebugString();
  EXPECT_EQ(reply.id(), 6u);
  EXPECT_EQ(reply.error().code(), msg::Error::INVALID);
  EXPECT_NE(reply.error().message().find("unknown key"), std::string::npos) << reply.error().message();
}

TEST_F(Daemon, ListsDevices) {
  client::ControlClient client(control_);
  msg::Request r;
  r.mutable_list_devices();
  const msg::Reply reply = client.call(r);
  ASSERT_TRUE(reply.has_devices()) << reply.DebugString();
  for (const msg::Device& d : reply.devices().devices()) {
    EXPECT_FALSE(d.uri().empty());
    EXPECT_FALSE(d.kind().empty());
  }
}

TEST_F(Daemon, ThinClientShowsStatus) {
  std::string out;
  const int rc =
      testing_support::run_command({testing_support::binary("plenopiv"), "--endpoint", control_, "status"}, out);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("state          Idle"), std::string::npos) << out;
}

// `--json` writes one JSON document on stdout alone: Python's json module reads it (and checks
// what it holds) straight from the pipe.
int json_check(const std::string& control, const std::string& command, const std::string& python_check,
               std::string& out) {
  const std::string line = testing_support::binary("plenopiv") + " --endpoint '" + control + "' " + command +
                           " --json | /usr/bin/python3 -c 'import json, sys; d = json.load(sys.stdin); " +
                           python_check + "'";
  return testing_support::run_command({"/bin/bash", "-c", "set -o pipefail; " + line}, out);
}

TEST_F(Daemon, StatusJsonIsTheStatusMessage) {
  std::string out;
  EXPECT_EQ(
      json_check(control_, "status", "assert d[\"state\"] == \"Idle\", d; assert \"pairs_acquired\" in d, d", out), 0)
      << out;
}

TEST_F(Daemon, DevicesJsonIsAnArrayThatListsTheSimulatedBackends) {
  std::string out;
  EXPECT_EQ(json_check(control_, "devices",
                       "assert isinstance(d, list), d; "
                       "assert {(x[\"uri\"], x[\"kind\"]) for x in d if x[\"simulated\"]} >= "
                       "{(\"sim://\", \"camera\"), (\"sim://\", \"trigger\")}, d",
                       out),
            0)
      << out;
  // The text form marks them too: never "no devices found" while sim:// exists.
  ASSERT_EQ(testing_support::run_command({testing_support::binary("plenopiv"), "--endpoint", control_, "devices"}, out),
            0)
      << out;
  EXPECT_NE(out.find("sim://"), std::string::npos) << out;
  EXPECT_NE(out.find("simulated plenoptic camera [simulated]"), std::string::npos) << out;
  EXPECT_NE(out.find("simulation: true"), std::string::npos) << out;  // how to enable it on this daemon
  EXPECT_EQ(out.find("no devices found"), std::string::npos) << out;
}

// The control options are the main program's; they are taken after the command as well.
TEST_F(Daemon, ControlOptionsWorkBeforeAndAfterTheCommand) {
  for (const auto& argv : {std::vector<std::string>{testing_support::binary("plenopiv"), "--endpoint", control_,
                                                    "--timeout", "2", "status"},
                           std::vector<std::string>{testing_support::binary("plenopiv"), "status", "--endpoint",
                                                    control_, "--timeout", "2"},
                           std::vector<std::string>{testing_support::binary("plenopiv"), "devices", "--timeout", "2",
                                                    "--endpoint=" + control_}}) {
    std::string out;
    EXPECT_EQ(testing_support::run_command(argv, out), 0) << argv[1] << ": " << out;
  }
}

TEST_F(Daemon, PublishesStatusOnItsTopic) {
  zmq::context_t ctx;
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::subscribe, "status");
  sub.set(zmq::sockopt::rcvtimeo, 5000);
  sub.connect(publish_);
  zmq::message_t topic, body;
  ASSERT_TRUE(sub.recv(topic, zmq::recv_flags::none)) << "no status published within 5 s";
  EXPECT_EQ(topic.to_string(), "status");
  ASSERT_TRUE(sub.get(zmq::sockopt::rcvmore));
  ASSERT_TRUE(sub.recv(body, zmq::recv_flags::none));
  msg::Status s;
  ASSERT_TRUE(s.ParseFromArray(body.data(), int(body.size())));
  EXPECT_EQ(s.state(), "Idle");
}

TEST(ControlClient, MissingDaemonIsAClearErrorAfterTheTimeout) {
  const std::string endpoint = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  client::ControlClient client(endpoint, 300ms);
  msg::Request r;
  r.mutable_status();
  const auto start = std::chrono::steady_clock::now();
  try {
    client.call(r);
    FAIL() << "a call to no daemon returned";
  } catch (const client::ControlError& e) {
    EXPECT_NE(std::string(e.what()).find("no reply from plenopivd at " + endpoint), std::string::npos) << e.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, 3s);  // a bound on hanging, not a timing figure
}

TEST(ThinClient, MissingDaemonExitsWithStatus3) {
  std::string out;
  const std::string endpoint = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  const int rc = testing_support::run_command(
      {testing_support::binary("plenopiv"), "--endpoint", endpoint, "--timeout", "0.3", "status"}, out);
  EXPECT_EQ(rc, 3) << out;
  EXPECT_NE(out.find("no reply from plenopivd"), std::string::npos) << out;
}

// `run start` waits long for the start's answer (a run's tables take seconds at paper scale),
// but asks for the status first within --timeout: no daemon is still a quick error.
TEST(ThinClient, RunStartToAMissingDaemonFailsWithinTheTimeout) {
  std::string out;
  const std::string endpoint = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  const auto start = std::chrono::steady_clock::now();
  const int rc = testing_support::run_command(
      {testing_support::binary("plenopiv"), "--endpoint", endpoint, "--timeout", "0.3", "run", "start", "--config",
       std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/run.yaml"},
      out);
  EXPECT_EQ(rc, 3) << out;
  EXPECT_NE(out.find("no reply from plenopivd"), std::string::npos) << out;
  EXPECT_LT(std::chrono::steady_clock::now() - start, 10s);  // not the start's 120 s wait
}

TEST(Plenopivd, RefusesATcpControlEndpointWithoutCurve) {
  for (const char* endpoint : {"tcp://0.0.0.0:5555", "tcp://127.0.0.1:5555"}) {
    std::string out;
    const int rc = testing_support::run_command({testing_support::binary("plenopivd"), "--control", endpoint}, out);
    EXPECT_EQ(rc, 2) << out;
    EXPECT_NE(out.find("control_endpoint"), std::string::npos) << out;
    EXPECT_NE(out.find("curve:"), std::string::npos) << out;
  }
}

// The local control socket admits the daemon's user and group only, whatever umask it was started
// with: another local user cannot start runs (or make the daemon do anything).
TEST(DaemonSocket, TheControlSocketAdmitsItsOwnerAndGroupOnly) {
  const std::string control = testing_support::ipc_endpoint("open-umask");
  const std::string file = control.substr(6);
  // umask 000 would leave a socket file anyone may open.
  ChildProcess daemon({"/bin/sh", "-c",
                       "umask 000; exec " + testing_support::binary("plenopivd") + " --control " + control +
                           " --publish tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port())},
                      std::filesystem::temp_directory_path() / "plenopiv-test" / "socket-mode.log");
  for (int i = 0; i < 100 && !testing_support::probe_status(control); ++i)
    ASSERT_TRUE(daemon.running()) << daemon.output();
  struct stat st {};
  ASSERT_EQ(::stat(file.c_str(), &st), 0) << file;
  EXPECT_TRUE(S_ISSOCK(st.st_mode));
  EXPECT_EQ(st.st_mode & 0777, 0660u) << std::oct << (st.st_mode & 0777);
  if (::geteuid() != 0 || ::access("/usr/sbin/runuser", X_OK) != 0) {
    GTEST_SKIP() << "needs root and runuser to try the socket as another user (nobody)";
  }
  // The folder is open to everyone, so only the socket's own mode keeps `nobody` out.
  std::filesystem::permissions(std::filesystem::path(file).parent_path(), std::filesystem::perms(0755));
  std::string out;
  const int rc =
      testing_support::run_command({"/usr/sbin/runuser", "-u", "nobody", "--", testing_support::binary("plenopiv"),
                                    "--endpoint", control, "--timeout", "1", "status"},
                                   out);
  EXPECT_EQ(rc, 3) << out;
  EXPECT_NE(out.find("no reply from plenopivd"), std::string::npos) << out;
  EXPECT_TRUE(testing_support::probe_status(control, 5s)) << "the owner still controls it";
}

// Oversized control messages are dropped by ZeroMQ before the daemon reads them; configs beyond the
// YAML limits are refused by name and quickly; the daemon serves on.
TEST_F(Daemon, OversizedAndHostileRequestsAreRefusedWithoutStallingTheDaemon) {
  {
    zmq::context_t ctx;
    zmq::socket_t req(ctx, zmq::socket_type::req);
    req.set(zmq::sockopt::linger, 0);
    req.set(zmq::sockopt::rcvtimeo, 1000);
    req.connect(control_);
    msg::Request r;
    r.mutable_start_run()->set_config_yaml(std::string(3 * 1024 * 1024, '#'));
    req.send(zmq::buffer(r.SerializeAsString()), zmq::send_flags::none);
    zmq::message_t answer;
    EXPECT_FALSE(req.recv(answer, zmq::recv_flags::none)) << "a 3 MiB request was read and answered";
  }
  client::ControlClient client(control_, 3000ms);
  const auto start_with = [&](const std::string& yaml) {
    msg::Request r;
    r.mutable_start_run()->set_config_yaml(yaml);
    return client.call(r);
  };
  const auto t0 = std::chrono::steady_clock::now();
  const msg::Reply big = start_with("# " + std::string(1536 * 1024, 'x') + "\npairs: 1\n");
  ASSERT_TRUE(big.has_error());
  EXPECT_EQ(big.error().code(), msg::Error::INVALID);
  EXPECT_NE(big.error().message().find("larger than 1024 KiB"), std::string::npos) << big.error().message();
  const msg::Reply deep = start_with("a: " + std::string(200, '[') + std::string(200, ']') + "\n");
  ASSERT_TRUE(deep.has_error());
  EXPECT_NE(deep.error().message().find("nested deeper than 32 levels"), std::string::npos) << deep.error().message();
  // Nine levels of ten aliases each stand for 10^9 nodes in a few hundred bytes.
  std::string laughs = "l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]\n";
  for (int i = 1; i <= 9; ++i) {
    laughs += "l" + std::to_string(i) + ": &l" + std::to_string(i) + " [";
    for (int k = 0; k < 10; ++k) laughs += std::string(k ? ", " : "") + "*l" + std::to_string(i - 1);
    laughs += "]\n";
  }
  const msg::Reply bomb = start_with(laughs);
  ASSERT_TRUE(bomb.has_error());
  EXPECT_NE(bomb.error().message().find("YAML nodes (aliases expanded)"), std::string::npos) << bomb.error().message();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);  // a bound on stalling, not a timing figure
  msg::Request status;
  status.mutable_status();
  EXPECT_TRUE(client.call(status).has_status());
}

// Requests never name files: a run config's device URIs cannot make the daemon open (or quote) a
// file, and the simulated camera exists only where the config enables it.
TEST_F(Daemon, DeviceUrisFromRequestsCannotNameFiles) {
  client::ControlClient client(control_, 3000ms);
  const auto refusal = [&](const std::string& camera_uri) {
    msg::Request r;
    r.mutable_start_run()->set_config_yaml(
        "camera_uri: \"" + camera_uri +
        "\"\ndt_s: 0.0001\nvolume: {x_mm: [0, 2], y_mm: [0, 2], z_mm: [0, 2], voxel_mm: "
        "0.5}\ncorrelation: {passes: [{window: 4, overlap_percent: 50}]}\n");
    const msg::Reply reply = client.call(r);
    EXPECT_TRUE(reply.has_error()) << camera_uri;
    EXPECT_EQ(reply.error().code(), msg::Error::INVALID) << reply.error().message();
    EXPECT_EQ(reply.error().message().find("root:"), std::string::npos) << reply.error().message();
    return reply.error().message();
  };
  // This daemon was started without simulation.
  EXPECT_NE(refusal("sim://?camera=/etc/passwd").find("not enabled on this daemon"), std::string::npos);
  const std::string replay = refusal("replay:///etc?rate_hz=10");
  EXPECT_NE(replay.find("replay:///etc?rate_hz=10"), std::string::npos) << replay;
  EXPECT_NE(replay.find("the replay camera is not enabled on this daemon"), std::string::npos) << replay;
  EXPECT_NE(refusal("aravis://127.0.0.1?profile=/etc/passwd").find("not a path"), std::string::npos);
  EXPECT_TRUE(daemon_->running());
}

// Device discovery (about a second for the Aravis and USB scans) runs off the control thread:
// a status request sent after a list_devices request is answered first.
TEST_F(Daemon, ListingDevicesDoesNotHoldTheControlLoop) {
  zmq::context_t ctx;
  zmq::socket_t dealer(ctx, zmq::socket_type::dealer);
  dealer.set(zmq::sockopt::linger, 0);
  dealer.set(zmq::sockopt::rcvtimeo, 5000);
  dealer.connect(control_);
  const auto send = [&](std::uint64_t id, bool list) {
    msg::Request r;
    r.set_id(id);
    if (list) {
      r.mutable_list_devices();
    } else {
      r.mutable_status();
    }
    dealer.send(zmq::str_buffer(""), zmq::send_flags::sndmore);  // REQ-style delimiter
    dealer.send(zmq::buffer(r.SerializeAsString()), zmq::send_flags::none);
  };
  send(1, true);
  std::this_thread::sleep_for(50ms);
  send(2, false);
  std::vector<std::uint64_t> order;
  for (int i = 0; i < 2; ++i) {
    zmq::message_t delimiter, body;
    ASSERT_TRUE(dealer.recv(delimiter, zmq::recv_flags::none)) << "no reply within 5 s";
    ASSERT_TRUE(dealer.recv(body, zmq::recv_flags::none));
    msg::Reply reply;
    ASSERT_TRUE(reply.ParseFromArray(body.data(), int(body.size())));
    order.push_back(reply.id());
    if (reply.id() == 1) {
      EXPECT_TRUE(reply.has_devices()) << reply.DebugString();
    }
  }
  EXPECT_EQ(order, (std::vector<std::uint64_t>{2, 1})) << "the status waited for the device scan";
}

// SIGTERM while pairs are being reconstructed (here at a thousand MART iterations each, minutes of
// work) ends the daemon within 10 s: the processing gives up at its next iteration, the camera and
// recorder drain within their bounds, and the folder is closed "stopped", listing what it holds.
TEST(DaemonStop, SigtermWithHeavyProcessingInFlightEndsWithinTenSeconds) {
  namespace fs = std::filesystem;
  const fs::path dir = fresh_dir("stop", "heavy");
  const std::string control = testing_support::ipc_endpoint("control");
  ChildProcess daemon(sim_daemon(control, dir / "data", "sim://?rays=300&ppm=0.3"), dir / "plenopivd.log");
  ASSERT_TRUE(answers(daemon, control)) << daemon.output();
  std::ofstream(dir / "heavy.yaml") << "pairs: 0\nrate_hz: 5\ndt_s: 0.0001\n"
                                       "volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [-3, 3], voxel_mm: 0.125}\n"
                                       "reconstruction: {iterations: 1000, mu: 1}\n"
                                       "max_pairs_in_flight: 2\n";
  std::string out;
  ASSERT_EQ(testing_support::run_command({testing_support::binary("plenopiv"), "--endpoint", control, "run", "start",
                                          "--config", (dir / "heavy.yaml").string()},
                                         out),
            0)
      << out;
  for (int i = 0; i < 200; ++i) {
    const auto s = testing_support::probe_status(control);
    if (s && s->pairs_recorded() >= 4) break;
    std::this_thread::sleep_for(50ms);
  }
  const auto t0 = std::chrono::steady_clock::now();
  daemon.signal(SIGTERM);
  const auto status = daemon.wait(30s);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(status.has_value()) << daemon.output();
  EXPECT_EQ(*status, 0) << daemon.output();
  EXPECT_LT(took, 10.0) << "SIGTERM took " << took << " s:\n" << daemon.output();
  fs::path run;
  for (const auto& e : fs::directory_iterator(dir / "data")) run = e.path();
  const msg::RunManifest m = testing_support::read_manifest(run);
  EXPECT_EQ(m.state(), "stopped");
  EXPECT_GE(m.pairs_size(), 4);
  EXPECT_GE(m.losses().processing_cancelled(), 1u) << m.losses().DebugString();
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_TRUE(fs::exists(run / p.frame_a()));
    EXPECT_TRUE(fs::exists(run / p.frame_b()));
  }
}

// plenopivd on the simulated small camera, runs whose settings ask for a depth response (the
// camera's shallow box, where MART follows depth shifts; two iterations and 0.2 particles per
// microlens: a test's time, most of it the simulator's frames; the response's accuracy is
// tests/e2e/depth_response_test.cpp's), and what its data directory keeps.
class DaemonSetup : public ::testing::Test {
 protected:
  // The longest a run's setup or the whole run is waited for: a depth response takes seconds, and
  // many times as long under ThreadSanitizer (.ci/run).
  static constexpr std::chrono::milliseconds kLongest = 4min;
  void start(const std::string& name) {
    dir_ = fresh_dir("setup", name);
    control_ = testing_support::ipc_endpoint("control");
    daemon_ = std::make_unique<ChildProcess>(sim_daemon(control_, dir_ / "data", "sim://?rays=300&ppm=0.3"),
                                             dir_ / "plenopivd.log");
    ASSERT_TRUE(answers(*daemon_, control_)) << daemon_->output();
  }
  // A run config in the test's folder: `run_keys`, the box, MART with a depth response, `more`.
  std::string config(const std::string& name, const std::string& run_keys, const std::string& more = "") {
    const std::filesystem::path file = dir_ / (name + ".yaml");
    std::ofstream(file) << run_keys + testing_support::kShallowSmallBox +
                               "reconstruction: {iterations: 2, mu: 1, acceleration: nesterov, "
                               "depth_response_ppm: 0.2}\n" +
                               more;
    return file.string();
  }
  // `plenopiv run ARGS` against the daemon; its output (the command must succeed). A `run start`
  // follows the setup (a depth response among it) until the run acquires: it gets kLongest too.
  std::string run(const std::vector<std::string>& args) {
    std::vector<std::string> command{testing_support::binary("plenopiv"), "--endpoint", control_, "run"};
    command.insert(command.end(), args.begin(), args.end());
    std::string out;
    EXPECT_EQ(testing_support::run_command(command, out, kLongest), 0) << out;
    return out;
  }
  std::filesystem::path responses() const { return dir_ / "data" / "depth-responses"; }
  // Depth responses kept, and run folders made, in the data directory.
  std::size_t kept() const { return testing_support::entries_named(responses(), "depth-response-"); }
  std::size_t runs() const { return testing_support::entries_named(dir_ / "data", "run-"); }
  // Whether the daemon goes Idle within kLongest.
  bool goes_idle() const {
    const auto deadline = std::chrono::steady_clock::now() + kLongest;
    while (std::chrono::steady_clock::now() < deadline) {
      const auto s = testing_support::probe_status(control_);
      if (s && s->state() == "Idle") return true;
      std::this_thread::sleep_for(50ms);
    }
    return false;
  }

  std::filesystem::path dir_;
  std::string control_;
  std::unique_ptr<ChildProcess> daemon_;
};

// A run whose settings ask for a depth response measures it while Armed, status saying how far;
// `run stop` then ends it with nothing made. A run that lets it finish keeps it in the data
// directory, and the next run on the same settings reads it back instead of measuring.
TEST_F(DaemonSetup, ADepthResponseIsMeasuredWhileArmedStoppableAndKeptForTheNextRun) {
  start("depth-response");
  const std::string response = config("response", "pairs: 1\nrate_hz: 5\ndt_s: 0.0001");
  run({"start", "--no-wait", "--config", response});
  std::string said;
  for (int i = 0; i < 600 && said.find("% measured") == std::string::npos; ++i) {
    if (const auto s = testing_support::probe_status(control_)) said = s->message();
    std::this_thread::sleep_for(20ms);
  }
  EXPECT_EQ(said.rfind("setting up: depth response of the full tier, ", 0), 0u) << said;
  run({"stop"});
  ASSERT_TRUE(goes_idle()) << daemon_->output();
  EXPECT_EQ(runs(), 0u);
  EXPECT_EQ(kept(), 0u);

  run({"start", "--config", response});
  ASSERT_TRUE(goes_idle()) << daemon_->output();
  EXPECT_EQ(kept(), 1u) << daemon_->output();
  run({"start", "--config", response});
  ASSERT_TRUE(goes_idle()) << daemon_->output();
  EXPECT_EQ(runs(), 2u);
  const std::string log = daemon_->output();
  const std::size_t measured = log.find("depth response measured and kept in the cache: " + responses().string());
  EXPECT_NE(measured, std::string::npos) << log;
  EXPECT_NE(log.find("depth response from the cache: " + responses().string(), measured), std::string::npos) << log;
}

// With a live tier, the quality lane's depth response is measured by its first pair while the run
// acquires: `run start` returns acquiring with no response made, and the quality lane's fields come
// once it is measured (and kept).
TEST_F(DaemonSetup, TheQualityLanesDepthResponseIsMeasuredByItsFirstPairWhileTheRunAcquires) {
  start("quality-response");
  const std::string lanes = config("lanes", "pairs: 4\nrate_hz: 2\ndt_s: 0.0001\nquality: newest",
                                   "live:\n"
                                   "  volume: {voxel_mm: 0.25, voxel_z_mm: 0.5}\n"
                                   "  reconstruction: {depth_response_ppm: 0}\n"
                                   "  correlation: {passes: [{window: [8, 8, 4], overlap_percent: 50}]}\n");
  const std::string out = run({"start", "--config", lanes});
  EXPECT_NE(out.find(" acquiring"), std::string::npos) << out;
  EXPECT_EQ(kept(), 0u) << "measured before the run acquired";
  ASSERT_TRUE(goes_idle()) << daemon_->output();
  EXPECT_EQ(kept(), 1u) << daemon_->output();
  std::filesystem::path run_dir;
  for (const auto& e : std::filesystem::directory_iterator(dir_ / "data"))
    if (e.path().filename().string().starts_with("run-")) run_dir = e.path();
  const msg::RunManifest m = testing_support::read_manifest(run_dir);
  EXPECT_EQ(m.state(), "complete");
  EXPECT_EQ(m.pairs_size(), 4);
  for (const msg::LaneCounters& lane : m.lanes()) EXPECT_GT(lane.processed(), 0u) << lane.name();
  const std::string log = daemon_->output();
  EXPECT_NE(log.find("depth response deferred to the first pair"), std::string::npos) << log;
  EXPECT_NE(
      log.find("run processing, full tier: depth response measured and kept in the cache: " + responses().string()),
      std::string::npos)
      << log;
}

// A disk that fills during a run ends the run as failed, naming the disk, with a consistent folder;
// the daemon stays controllable and refuses a new run that would not fit, saying how much is free.
TEST(DaemonDisk, AFullDiskFailsTheRunCleanlyAndRefusesTheNext) {
  namespace fs = std::filesystem;
  const fs::path dir = testing_support::temp_dir("disk");
  testing_support::SmallTmpfs disk(dir / "data", 110);
  if (!disk.mounted()) GTEST_SKIP() << disk.why_not();
  const std::string control = testing_support::ipc_endpoint("control");
  ChildProcess daemon(sim_daemon(control, disk.dir(), "sim://?rays=100&ppm=0.05"), dir / "plenopivd.log");
  ASSERT_TRUE(answers(daemon, control)) << daemon.output();
  // 2.9 MB of raw frames per pair (850 x 850 px, 16 bit): the 110 MB disk holds about 30.
  std::ofstream(dir / "long.yaml") << "pairs: 0\nrate_hz: 10\ndt_s: 0.0001\n"
                                      "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-1, 1], voxel_mm: 0.25}\n"
                                      "reconstruction: {iterations: 1}\n"
                                      "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n";
  const auto start = [&](std::string& out) {
    return testing_support::run_command({testing_support::binary("plenopiv"), "--endpoint", control, "run", "start",
                                         "--config", (dir / "long.yaml").string()},
                                        out);
  };
  std::string out;
  ASSERT_EQ(start(out), 0) << out;
  std::optional<msg::Status> s;
  for (int i = 0; i < 400; ++i) {
    s = testing_support::probe_status(control);
    if (s && s->state() == "Error") break;
    std::this_thread::sleep_for(50ms);
  }
  ASSERT_TRUE(s);
  ASSERT_EQ(s->state(), "Error") << daemon.output();
  EXPECT_NE(s->message().find("no space left on device"), std::string::npos) << s->message();
  const fs::path run = testing_support::only_run_folder(disk.dir());
  const msg::RunManifest m = testing_support::read_manifest(run);
  EXPECT_EQ(m.state().rfind("failed: no space left on device", 0), 0u) << m.state();
  EXPECT_GT(m.pairs_size(), 10);
  for (const msg::ManifestPair& p : m.pairs()) {
    EXPECT_TRUE(fs::exists(run / p.frame_a())) << p.frame_a();
    EXPECT_TRUE(fs::exists(run / p.frame_b())) << p.frame_b();
  }
  // Still controllable; a new run is refused up front, naming the free space.
  EXPECT_EQ(start(out), 4) << out;
  EXPECT_NE(out.find("data_dir: " + disk.dir().string() + " has"), std::string::npos) << out;
  EXPECT_NE(out.find("free some space or record fewer pairs"), std::string::npos) << out;
  // A duration beyond any count of pairs is refused for its disk, not converted out of range.
  std::ofstream(dir / "endless.yaml") << "duration_s: 1e300\nrate_hz: 10\ndt_s: 0.0001\n"
                                         "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-1, 1], voxel_mm: 0.25}\n"
                                         "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n";
  EXPECT_EQ(testing_support::run_command({testing_support::binary("plenopiv"), "--endpoint", control, "run", "start",
                                          "--config", (dir / "endless.yaml").string()},
                                         out),
            4)
      << out;
  EXPECT_NE(out.find("18446744073709551615 pairs of raw frames need"), std::string::npos) << out;
  EXPECT_TRUE(testing_support::probe_status(control, 5s));
  daemon.signal(SIGTERM);
  EXPECT_TRUE(daemon.wait(10s).has_value());
}

// CURVE: over tcp:// the daemon admits only the clients whose public keys it was given, for control
// and (curve.publish) for its published data.
TEST(DaemonCurve, AdmitsOnlyAuthorizedKeysOverTcp) {
  namespace fs = std::filesystem;
  const fs::path dir = testing_support::temp_dir("curve");
  fs::remove_all(dir);
  fs::create_directories(dir / "clients");
  std::string out;
  for (const auto& [name, where] :
       {std::pair{"plenopivd", dir}, std::pair{"desk", dir / "clients"}, std::pair{"stranger", dir}}) {
    ASSERT_EQ(
        testing_support::run_command({testing_support::binary("plenopiv"), "keys", name, "-o", where.string()}, out), 0)
        << out;
  }
  EXPECT_EQ(fs::status(dir / "plenopivd.key_secret").permissions() & fs::perms::all,
            fs::perms::owner_read | fs::perms::owner_write);
  std::ofstream(dir / "plenopivd.yaml") << "curve: {server_certificate: plenopivd.key_secret, "
                                           "authorized_clients: clients, publish: true}\n";
  const std::string control = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  const std::string publish = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
  ChildProcess daemon({testing_support::binary("plenopivd"), "--config", (dir / "plenopivd.yaml").string(), "--control",
                       control, "--publish", publish, "--data-dir", (dir / "data").string()},
                      dir / "plenopivd.log");
  const auto status_as = [&](const std::vector<std::string>& keys) {
    std::vector<std::string> argv{testing_support::binary("plenopiv"), "--endpoint", control, "--timeout", "1"};
    argv.insert(argv.end(), keys.begin(), keys.end());
    argv.push_back("status");
    return testing_support::run_command(argv, out);
  };
  const std::vector<std::string> desk{"--server-key", (dir / "plenopivd.key").string(), "--client-cert",
                                      (dir / "clients" / "desk.key_secret").string()};
  int rc = 3;
  for (int i = 0; i < 50 && (rc = status_as(desk)) != 0; ++i) ASSERT_TRUE(daemon.running()) << daemon.output();
  ASSERT_EQ(rc, 0) << out << daemon.output();
  EXPECT_NE(out.find("state          Idle"), std::string::npos) << out;
  // A key the daemon was not given, and no key at all, get no answer.
  EXPECT_EQ(status_as({"--server-key", (dir / "plenopivd.key").string(), "--client-cert",
                       (dir / "stranger.key_secret").string()}),
            3)
      << out;
  EXPECT_NE(out.find("does it admit this client's key"), std::string::npos) << out;
  EXPECT_EQ(status_as({}), 3) << out;
  EXPECT_NE(out.find("needs CURVE"), std::string::npos) << out;
  // Half a key pair is a usage error, named.
  EXPECT_EQ(status_as({"--server-key", (dir / "plenopivd.key").string()}), 2) << out;
  EXPECT_NE(daemon.output().find("refused a CURVE connection"), std::string::npos) << daemon.output();

  // Publishing: the authorized subscriber gets the status topic, a stranger gets nothing.
  const auto first_status = [&](const std::string& client_cert) {
    zmq::context_t ctx;
    zmq::socket_t sub(ctx, zmq::socket_type::sub);
    sub.set(zmq::sockopt::linger, 0);
    sub.set(zmq::sockopt::rcvtimeo, 2500);
    sub.set(zmq::sockopt::subscribe, "status");
    wire::secure_client(sub, wire::client_security(dir / "plenopivd.key", client_cert));
    sub.connect(publish);
    zmq::message_t topic;
    return bool(sub.recv(topic, zmq::recv_flags::none));
  };
  EXPECT_TRUE(first_status((dir / "clients" / "desk.key_secret").string()));
  EXPECT_FALSE(first_status((dir / "stranger.key_secret").string()));
  // The Python subscriber loads the same certificate files (zmq.auth) and connects with them: no run
  // is going, so it waits and says so (exit 3), with no traceback.
  const int py =
      testing_support::run_command({PLENOPIV_PACKAGE_PYTHON, "-m", "plenopiv.subscribe", "--publish", publish,
                                    "--server-key", (dir / "plenopivd.key").string(), "--client-cert",
                                    (dir / "clients" / "desk.key_secret").string(), "--count", "1", "--wait", "1"},
                                   out);
  EXPECT_EQ(py, 3) << out;
  EXPECT_EQ(out.find("Traceback"), std::string::npos) << out;
  daemon.signal(SIGTERM);
  EXPECT_TRUE(daemon.wait(10s).has_value());
}

}  // namespace
}  // namespace plenopiv
