// plenopivd as a real child process on real ZeroMQ sockets: replies, bad messages, timeouts, SIGTERM.
#include <gtest/gtest.h>

#include <csignal>
#include <thread>
#include <zmq.hpp>

#include "clients/cli/control_client.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/daemon_status.hpp"

namespace plenopiv {
namespace {

using namespace std::chrono_literals;
using testing_support::ChildProcess;

class Daemon : public ::testing::Test {
 protected:
  void SetUp() override {
    control_ = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
    publish_ = "tcp://127.0.0.1:" + std::to_string(testing_support::free_tcp_port());
    daemon_ = std::make_unique<ChildProcess>(
        std::vector<std::string>{testing_support::binary("plenopivd"), "--control", control_,
                                 "--publish", publish_, "--log-level", "info"},
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
  const int rc = testing_support::run_command(
      {testing_support::binary("plenopiv"), "--endpoint", control_, "status"}, out);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("state          Idle"), std::string::npos) << out;
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
    EXPECT_NE(std::string(e.what()).find("no reply from plenopivd at " + endpoint), std::string::npos)
        << e.what();
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
  const int rc = testing_support::run_command({testing_support::binary("plenopiv"), "--endpoint", endpoint, "--timeout",
                                               "0.3", "run", "start", "--config",
                                               std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/run.yaml"},
                                              out);
  EXPECT_EQ(rc, 3) << out;
  EXPECT_NE(out.find("no reply from plenopivd"), std::string::npos) << out;
  EXPECT_LT(std::chrono::steady_clock::now() - start, 10s);  // not the start's 120 s wait
}

TEST(Plenopivd, RefusesARemoteControlEndpoint) {
  std::string out;
  const int rc = testing_support::run_command(
      {testing_support::binary("plenopivd"), "--control", "tcp://0.0.0.0:5555"}, out);
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("control_endpoint"), std::string::npos) << out;
}

}  // namespace
}  // namespace plenopiv
