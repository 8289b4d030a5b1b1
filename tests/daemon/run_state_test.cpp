// The run state machine: legal paths, and illegal requests refused with a clear error, changing nothing.
#include <gtest/gtest.h>

#include "daemon/run_state.hpp"

namespace plenopiv::daemon {
namespace {

// Expects `call` to throw WrongStateError mentioning `words`, and the machine to be unchanged.
template <typename F>
void expect_refused(RunStateMachine& m, F call, const std::string& words) {
  const RunState before = m.state();
  const std::string run_before = m.run_id();
  try {
    call();
    FAIL() << "not refused in state " << to_string(before);
  } catch (const WrongStateError& e) {
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(to_string(before)), std::string::npos) << e.what();
  }
  EXPECT_EQ(m.state(), before);
  EXPECT_EQ(m.run_id(), run_before);
}

TEST(RunState, RunGoesIdleArmedAcquiringDrainingIdle) {
  RunStateMachine m;
  EXPECT_EQ(m.state(), RunState::Idle);
  m.start("r1");
  EXPECT_EQ(m.state(), RunState::Armed);
  EXPECT_EQ(m.run_id(), "r1");
  m.acquiring();
  EXPECT_EQ(m.state(), RunState::Acquiring);
  m.stop();
  EXPECT_EQ(m.state(), RunState::Draining);
  m.finishing();  // the run thread reaching its end while already draining is fine
  EXPECT_EQ(m.state(), RunState::Draining);
  m.drained();
  EXPECT_EQ(m.state(), RunState::Idle);
}

TEST(RunState, RunThatReachesItsPairCountDrainsByItself) {
  RunStateMachine m;
  m.start("r1");
  m.acquiring();
  m.finishing();
  EXPECT_EQ(m.state(), RunState::Draining);
  m.drained();
  EXPECT_EQ(m.state(), RunState::Idle);
}

TEST(RunState, StopWhileArmingLeadsToDraining) {
  RunStateMachine m;
  m.start("r1");
  m.stop();
  m.acquiring();  // the run thread finishes arming after the stop: it stays Draining
  EXPECT_EQ(m.state(), RunState::Draining);
}

TEST(RunState, StopWhenIdleIsRefused) {
  RunStateMachine m;
  expect_refused(
      m, [&] { m.stop(); }, "no run to stop");
}

TEST(RunState, StartWhenRunningIsRefused) {
  RunStateMachine m;
  m.start("r1");
  expect_refused(
      m, [&] { m.start("r2"); }, "cannot start a run");
  m.acquiring();
  expect_refused(
      m, [&] { m.start("r2"); }, "cannot start a run");
  m.stop();
  expect_refused(
      m, [&] { m.start("r2"); }, "cannot start a run");
  EXPECT_EQ(m.run_id(), "r1");
}

TEST(RunState, StopWhileDrainingIsRefused) {
  RunStateMachine m;
  m.start("r1");
  m.acquiring();
  m.stop();
  expect_refused(
      m, [&] { m.stop(); }, "already stopping");
}

TEST(RunState, CalibrationDuringARunIsRefused) {
  RunStateMachine m;
  EXPECT_NO_THROW(m.check_calibration_allowed());
  m.start("r1");
  expect_refused(
      m, [&] { m.check_calibration_allowed(); }, "calibration");
  m.acquiring();
  expect_refused(
      m, [&] { m.check_calibration_allowed(); }, "calibration");
  m.stop();
  expect_refused(
      m, [&] { m.check_calibration_allowed(); }, "calibration");
}

TEST(RunState, ErrorIsReportedAndLeftByStopOrANewStart) {
  RunStateMachine m;
  m.start("r1");
  m.acquiring();
  m.fail("camera lost");
  EXPECT_EQ(m.state(), RunState::Error);
  EXPECT_EQ(m.error(), "camera lost");
  EXPECT_NO_THROW(m.check_calibration_allowed());
  m.stop();
  EXPECT_EQ(m.state(), RunState::Idle);
  EXPECT_EQ(m.error(), "");
  m.fail("recorder: disk full");
  m.start("r2");
  EXPECT_EQ(m.state(), RunState::Armed);
  EXPECT_EQ(m.error(), "");
}

TEST(RunState, RunThreadStepsOutOfOrderAreBugs) {
  RunStateMachine m;
  EXPECT_THROW(m.acquiring(), std::logic_error);
  EXPECT_THROW(m.finishing(), std::logic_error);
  EXPECT_THROW(m.drained(), std::logic_error);
  EXPECT_EQ(m.state(), RunState::Idle);
}

}  // namespace
}  // namespace plenopiv::daemon
