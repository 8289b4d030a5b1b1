// plenopivd.yaml: defaults, relative paths, and refused endpoints and keys.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/base/errors.hpp"
#include "daemon/daemon_config.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::daemon {
namespace {

std::filesystem::path write_temp(const std::string& name, const std::string& text) {
  const auto path = testing_support::temp_dir("config-test") / name;
  std::ofstream(path) << text;
  return path;
}

std::string error_of(const std::string& text) {
  try {
    load_daemon_config(write_temp("bad.yaml", text));
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(DaemonConfig, ShippedDefaultLoads) {
  const DaemonConfig c = load_daemon_config(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/plenopivd.yaml");
  EXPECT_EQ(c.control_endpoint, "ipc:///run/plenopiv/control");
  EXPECT_EQ(c.publish_endpoint, "tcp://127.0.0.1:5556");
  EXPECT_TRUE(c.simulation);
  EXPECT_TRUE(std::filesystem::exists(c.camera_file)) << c.camera_file;
  EXPECT_TRUE(c.calibration_file.empty());  // nominal until the rig is calibrated
  EXPECT_EQ(c.processing_nice, 10);
}

TEST(DaemonConfig, RelativePathsAreTakenFromTheConfigFolder) {
  const auto path = write_temp("rel.yaml", "data_dir: runs\ncamera_file: cams/c.yaml\n");
  const DaemonConfig c = load_daemon_config(path);
  EXPECT_EQ(c.data_dir, path.parent_path() / "runs");
  EXPECT_EQ(c.camera_file, path.parent_path() / "cams/c.yaml");
}

TEST(DaemonConfig, CalibrationFileIsTakenFromTheConfigFolderAndNeedsTheCamera) {
  const auto path = write_temp("cal.yaml", "camera_file: c.yaml\ncalibration_file: rig/calibration.h5\n");
  EXPECT_EQ(load_daemon_config(path).calibration_file, path.parent_path() / "rig/calibration.h5");
  const std::string err = error_of("calibration_file: /etc/plenopiv/rig.h5\n");
  EXPECT_NE(err.find("calibration_file: '/etc/plenopiv/rig.h5' needs camera_file"), std::string::npos) << err;
}

TEST(DaemonConfig, TcpControlEndpointsNeedCurveLocalOnesToo) {
  for (const char* endpoint : {"tcp://*:5555", "tcp://127.0.0.1:5555", "tcp://localhost:5555"}) {
    const std::string err = error_of(std::string("control_endpoint: ") + endpoint + "\n");
    EXPECT_NE(err.find("control_endpoint"), std::string::npos) << err;
    EXPECT_NE(err.find("curve:"), std::string::npos) << err;
  }
  const auto path = write_temp("curve.yaml",
                               "control_endpoint: tcp://*:5555\n"
                               "curve: {server_certificate: keys/d.key_secret, authorized_clients: keys/clients, "
                               "publish: true}\n");
  const DaemonConfig c = load_daemon_config(path);
  ASSERT_TRUE(c.curve);
  EXPECT_EQ(c.curve->server_certificate, path.parent_path() / "keys/d.key_secret");
  EXPECT_EQ(c.curve->authorized_clients, path.parent_path() / "keys/clients");
  EXPECT_TRUE(c.curve->publish);
  EXPECT_NE(error_of("curve: {server_certificate: a.key_secret}\n").find("curve.authorized_clients: missing"),
            std::string::npos)
      << error_of("curve: {server_certificate: a.key_secret}\n");
  EXPECT_NE(error_of("control_endpoint: tcp://*:1\ncontrol_socket_group: plenopiv\n"
                     "curve: {server_certificate: a, authorized_clients: b}\n")
                .find("control_socket_group: only an ipc://"),
            std::string::npos);
}

TEST(DaemonConfig, TheSimulatedCameraExistsOnlyWhereTheConfigEnablesIt) {
  EXPECT_FALSE(DaemonConfig{}.simulation);  // built-in default: real devices only
  const std::string err = error_of("camera_uri: sim://?seed=1\n");
  EXPECT_NE(err.find("simulation: true"), std::string::npos) << err;
  EXPECT_EQ(error_of("camera_uri: sim://?seed=1\nsimulation: true\n"), "");
}

// replay:// reads files: like sim:// it needs simulation, and it reads only under replay_dir.
TEST(DaemonConfig, TheReplayCameraExistsOnlyWithSimulationAndReadsUnderReplayDir) {
  EXPECT_TRUE(DaemonConfig{}.replay_dir.empty());  // built-in default: no replay camera
  const std::string err = error_of("camera_uri: replay://recorded?rate_hz=10\n");
  EXPECT_NE(err.find("camera_uri: 'replay://recorded?rate_hz=10' is the replay camera"), std::string::npos) << err;
  EXPECT_NE(err.find("simulation: true"), std::string::npos) << err;
  const std::string dir_err = error_of("replay_dir: recordings\n");
  EXPECT_NE(dir_err.find("replay_dir: '"), std::string::npos) << dir_err;
  EXPECT_NE(dir_err.find("simulation: true"), std::string::npos) << dir_err;
  const auto path = write_temp("replay.yaml", "simulation: true\nreplay_dir: recordings\ncamera_uri: replay://a\n");
  EXPECT_EQ(load_daemon_config(path).replay_dir, path.parent_path() / "recordings");
}

TEST(DaemonConfig, BadKeysAreNamed) {
  EXPECT_NE(error_of("contrl_endpoint: tcp://127.0.0.1:1\n").find("contrl_endpoint: unknown key"), std::string::npos);
  EXPECT_NE(error_of("publish_endpoint: 5556\n").find("publish_endpoint"), std::string::npos);
  EXPECT_NE(error_of("log_level: loud\n").find("log_level"), std::string::npos);
  EXPECT_NE(error_of("publish_high_water_mark: 0\n").find("publish_high_water_mark"), std::string::npos);
  EXPECT_NE(error_of("processing_nice: 20\n").find("processing_nice"), std::string::npos);
}

TEST(DaemonConfig, TimingSectionSetsTheRigAndBadKeysAreNamed) {
  const DaemonConfig c = load_daemon_config(write_temp("t.yaml", "timing: {laser_max_rate_hz: 30, frame_b_s: 0.01}\n"));
  EXPECT_DOUBLE_EQ(c.timing.limits.laser_max_rate_hz, 30);
  EXPECT_DOUBLE_EQ(c.timing.limits.frame_b_s, 0.01);
  EXPECT_DOUBLE_EQ(c.timing.request.exposure_a_s, drivers::TimingRequest{}.exposure_a_s);
  EXPECT_NE(error_of("timing: {laser_rate_hz: 30}\n").find("timing.laser_rate_hz: unknown key"), std::string::npos)
      << error_of("timing: {laser_rate_hz: 30}\n");
  EXPECT_NE(error_of("timing: {frame_b_s: -1}\n").find("timing.frame_b_s"), std::string::npos);
}

TEST(RunSchedule, FullSequenceForQSwitchLinesGateAloneForHardwareTimedMode) {
  const RigTiming rig;
  drivers::TriggerInfo sim{"sim://", "sim", 0, {drivers::kTriggerLines.begin(), drivers::kTriggerLines.end()},
                           true,     true};
  const drivers::Schedule full = run_schedule(rig, sim, 10, 1e-3);
  EXPECT_NEAR(full.dt_s(), 1e-3, 1e-12);
  EXPECT_DOUBLE_EQ(full.period_s, 0.1);
  drivers::TriggerInfo gate{"gpiod://gpiochip0?gate=5", "gpiod", 50e-6, {drivers::TriggerLine::Gate}, false, false};
  const drivers::Schedule g = run_schedule(rig, gate, 10, 1e-3);
  ASSERT_EQ(g.edges.size(), 2u);
  EXPECT_EQ(g.edges[0].line, drivers::TriggerLine::Gate);
  // User-space GPIO cannot place the full sequence's 10 us margins: refused, pointing to gate mode.
  drivers::TriggerInfo coarse = sim;
  coarse.timing_uncertainty_s = 50e-6;
  try {
    run_schedule(rig, coarse, 10, 1e-3);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("hardware-timed"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace plenopiv::daemon
