// The live path in-process: ordering, skip-to-newest, recording of every pair, run folder contents,
// and a subscriber that never reads; pipeline cases rerun at several concurrency levels.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <tbb/global_control.h>
#include <atomic>
#include <cmath>
#include <cstring>
#include <future>
#include <iterator>

#include <fstream>
#include <latch>
#include <map>
#include <optional>
#include <sstream>
#include <thread>

#include "core/base/errors.hpp"
#include "core/io/direct_writer.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/publisher.hpp"
#include "daemon/run.hpp"
#include "drivers/sim/sim_camera.hpp"
#include "drivers/trigger/sim_trigger.hpp"
#include "tests/drivers/test_camera.hpp"
#include "tests/support/captured_log.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"
#include "tests/support/tmpfs.hpp"

namespace plenopiv::daemon {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

drivers::FramePair make_pair(std::uint64_t index) {
  drivers::FramePair p;
  p.pair_index = index;
  p.trigger_index = index;
  for (drivers::Frame* f : {&p.a, &p.b}) {
    f->image = ImageU16(8, 6, std::uint16_t(index + (f == &p.b ? 1000 : 0)));
    f->frame_id = 2 * index + (f == &p.b ? 2 : 1);
    f->host_timestamp_ns = 1'000'000'000ull * (index + 1);
    f->device_timestamp_ns = 1'000'000ull * index + (f == &p.b ? 100'000 : 0) + 1;
  }
  return p;
}

// A field whose x displacement is the pair index (mm): tells which pair a result came from.
ProcessedPair tagged_field(const drivers::FramePair& pair) {
  Grid3 g;
  g.shape = {3, 2, 2};
  ProcessedPair out;
  out.vectors = VectorField(g);
  out.vectors.dt_s = 1e-3;
  for (std::size_t i = 0; i < g.count(); ++i) {
    out.vectors.dx_mm[i] = float(pair.pair_index);
    out.vectors.valid[i] = 1;
  }
  return out;
}

using testing_support::read_manifest;

class Concurrency : public ::testing::TestWithParam<int> {};

TEST_P(Concurrency, OutputSeesEveryTakenPairInOrderWithItsOwnResult) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, GetParam());
  LiveMailbox mailbox;
  PipelineStats stats;
  std::vector<std::uint64_t> seen;
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < 40; ++i) {
      mailbox.push(std::make_shared<const drivers::FramePair>(make_pair(i)));
      if (i % 3 == 0) std::this_thread::sleep_for(1ms);
    }
    mailbox.close();
  });
  CancelFlag cancel{false};
  run_live_pipeline(
      mailbox, 3, [](const drivers::FramePair& pair, const PairSteps&) { return tagged_field(pair); },
      [&](const drivers::FramePair& pair, ProcessedPair& result) {
        EXPECT_EQ(result.vectors.dx_mm[0], float(pair.pair_index));
        seen.push_back(pair.pair_index);
      },
      stats, cancel);
  producer.join();
  ASSERT_FALSE(seen.empty());
  for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_LT(seen[i - 1], seen[i]);
  EXPECT_EQ(seen.back(), 39u);  // the newest pair is never skipped
  EXPECT_EQ(stats.output.processed + mailbox.dropped(), 40u);
  EXPECT_EQ(stats.process.processed, stats.output.processed);
}

TEST_P(Concurrency, SlowProcessingSkipsToTheNewestPairAndCountsTheRest) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, GetParam());
  LiveMailbox mailbox;
  PipelineStats stats;
  std::latch release(1);
  std::atomic<bool> first_taken{false};
  std::vector<std::uint64_t> seen;
  std::thread feeder([&] {
    mailbox.push(std::make_shared<const drivers::FramePair>(make_pair(0)));
    // Pair 0 is taken and blocks in processing (bounded: a pipeline that never takes it fails below).
    for (int i = 0; i < 30000 && !first_taken; ++i) std::this_thread::sleep_for(1ms);
    for (std::uint64_t i = 1; i <= 10; ++i) {
      mailbox.push(std::make_shared<const drivers::FramePair>(make_pair(i)));
    }
    release.count_down();
    mailbox.close();
  });
  CancelFlag cancel{false};
  run_live_pipeline(
      mailbox, 1,
      [&](const drivers::FramePair& pair, const PairSteps&) {
        if (pair.pair_index == 0) first_taken = true;
        release.wait();
        return tagged_field(pair);
      },
      [&](const drivers::FramePair& pair, ProcessedPair&) { seen.push_back(pair.pair_index); }, stats, cancel);
  feeder.join();
  // One pair in flight: pair 0 blocks; when it finishes, the input takes the newest (10).
  EXPECT_EQ(seen, (std::vector<std::uint64_t>{0, 10}));
  EXPECT_EQ(mailbox.dropped(), 9u);
}

TEST_P(Concurrency, TheLiveQueueStaysBoundedAtAnyRateAndCountsWhatItDrops) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, GetParam());
  LiveMailbox mailbox(3);
  PipelineStats stats;
  std::atomic<std::size_t> deepest{0};
  std::thread producer([&] {
    // Far faster than the processing below: without a bound the queue would hold most of them.
    for (std::uint64_t i = 0; i < 500; ++i) {
      mailbox.push(std::make_shared<const drivers::FramePair>(make_pair(i)));
      deepest = std::max(deepest.load(), mailbox.depth());
    }
    mailbox.close();
  });
  CancelFlag cancel{false};
  run_live_pipeline(
      mailbox, 2,
      [](const drivers::FramePair& pair, const PairSteps&) {
        std::this_thread::sleep_for(2ms);
        return tagged_field(pair);
      },
      [](const drivers::FramePair&, ProcessedPair&) {}, stats, cancel);
  producer.join();
  EXPECT_LE(deepest.load(), 3u);
  EXPECT_GT(mailbox.dropped(), 0u);
  EXPECT_EQ(stats.output.processed + mailbox.dropped(), 500u) << "every pair processed or counted dropped";
}

TEST_P(Concurrency, ACancelGivesUpThePairsInFlightAtTheirNextCheck) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, GetParam());
  LiveMailbox mailbox;
  PipelineStats stats;
  CancelFlag cancel{false};
  std::atomic<int> started{0};
  std::thread feeder([&] {
    mailbox.push(std::make_shared<const drivers::FramePair>(make_pair(0)));
    while (started == 0) std::this_thread::sleep_for(1ms);
    cancel = true;  // what Run::request_stop sets
    mailbox.close_and_clear();
  });
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::uint64_t> seen;
  run_live_pipeline(
      mailbox, 2,
      [&](const drivers::FramePair& pair, const PairSteps& c) {
        ++started;
        // Work in "iterations" that take a step, as MART and the correlation do through
        // process_pair's progress callback; without a cancel this would take 60 s.
        for (int iteration = 0; iteration < 6000; ++iteration) {
          c.step();
          std::this_thread::sleep_for(10ms);
        }
        return tagged_field(pair);
      },
      [&](const drivers::FramePair& pair, ProcessedPair&) { seen.push_back(pair.pair_index); }, stats, cancel);
  feeder.join();
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(took, 5.0) << "the pipeline did not give up its pair in flight";
  EXPECT_TRUE(seen.empty());
  EXPECT_EQ(stats.process.cancelled, 1u);
  EXPECT_EQ(stats.process.skipped, 0u) << "a cancelled pair is not a failed one";
}

// How far a long step is: the fraction, the time so far, and the time left at that pace once
// under way and not done; seconds up to a minute and a half, minutes beyond.
TEST(MeasuredSoFar, SaysTheFractionTheTimeSoFarAndAboutHowLongIsLeft) {
  EXPECT_EQ(measured_so_far(0.0, 12.4), "0 % measured, 12 s so far");
  EXPECT_EQ(measured_so_far(0.25, 60), "25 % measured, 60 s so far, about 3 min left");
  EXPECT_EQ(measured_so_far(0.5, 30), "50 % measured, 30 s so far, about 30 s left");
  EXPECT_EQ(measured_so_far(0.4, 120), "40 % measured, 2 min so far, about 3 min left");
  EXPECT_EQ(measured_so_far(1.0, 300), "100 % measured, 5 min so far");
}

// What a pair says it is doing beyond processing is the stage's activity while it is in flight,
// and is gone once it ends, whether it succeeded or threw.
TEST_P(Concurrency, WhatAPairSaysItDoesIsShownWhileItIsInFlight) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, GetParam());
  for (const bool fails : {false, true}) {
    LiveMailbox mailbox;
    PipelineStats stats;
    CancelFlag cancel{false};
    std::vector<std::string> during;
    mailbox.push(std::make_shared<const drivers::FramePair>(make_pair(0)));
    mailbox.close();
    run_live_pipeline(
        mailbox, 1,
        [&](const drivers::FramePair& pair, const PairSteps& steps) {
          during.push_back(stats.activity.text());
          steps.say("depth response of the full tier, 40 % measured");
          during.push_back(stats.activity.text());
          if (fails) throw InputError("a frame that does not fit");
          return tagged_field(pair);
        },
        [&](const drivers::FramePair&, ProcessedPair&) { during.push_back(stats.activity.text()); }, stats, cancel);
    ASSERT_EQ(during.size(), fails ? 2u : 3u);
    EXPECT_EQ(during[0], "");
    EXPECT_EQ(during[1], "depth response of the full tier, 40 % measured");
    if (!fails) {
      EXPECT_EQ(during[2], "") << "still said at the output stage";
    }
    EXPECT_EQ(stats.activity.text(), "") << (fails ? "after a failed pair" : "after the pair");
  }
}

TEST_P(Concurrency, AProcessingFailureSkipsThatPairOnly) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, GetParam());
  PipelineStats stats;
  std::vector<std::uint64_t> seen;
  // Fed one at a time so nothing is skipped for lateness.
  LiveMailbox one_by_one;
  std::thread feeder([&] {
    for (std::uint64_t i = 0; i < 3; ++i) {
      one_by_one.push(std::make_shared<const drivers::FramePair>(make_pair(i)));
      while (one_by_one.depth() > 0) std::this_thread::sleep_for(1ms);
      std::this_thread::sleep_for(20ms);
    }
    one_by_one.close();
  });
  CancelFlag cancel{false};
  run_live_pipeline(
      one_by_one, 2,
      [&](const drivers::FramePair& pair, const PairSteps&) {
        if (pair.pair_index == 1) throw std::runtime_error("no particles");
        return tagged_field(pair);
      },
      [&](const drivers::FramePair& pair, ProcessedPair&) { seen.push_back(pair.pair_index); }, stats, cancel);
  feeder.join();
  EXPECT_EQ(seen, (std::vector<std::uint64_t>{0, 2}));
  EXPECT_EQ(stats.process.skipped, 1u);
  EXPECT_EQ(one_by_one.dropped(), 0u);
}

INSTANTIATE_TEST_SUITE_P(Threads, Concurrency, ::testing::Values(1, 2, 4));

// A whole run in-process on the test camera.
class RunTest : public ::testing::Test {
 protected:
  void SetUp() override {
    testing_support::register_test_camera(drivers::CameraRegistry::instance());
    data_ = testing_support::temp_dir("daemon") / ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(data_);
    env_.data_dir = data_;
    env_.default_camera_uri = "test://";
    env_.default_trigger_uri = "sim://";
    env_.state = &state_;
    env_.processing = [](const RunConfig&, const RunCalibration&, process::Tier, const SetupProgress&) {
      return ProcessFn([](const drivers::FramePair& pair, const PairSteps&) { return tagged_field(pair); });
    };
    // Faster than a real laser, so runs stay short: frame B must end within the period.
    env_.timing.limits.laser_max_rate_hz = 200;
    env_.timing.limits.camera_max_pair_rate_hz = 200;
    env_.timing.limits.frame_b_s = 2e-3;
  }

  RunConfig config(const std::string& extra) {
    return parse_run_config((extra.find("dt_s:") == std::string::npos ? "dt_s: 0.0001\n" : "") +
                                std::string("volume: {x_mm: [0, 2], y_mm: [0, 2], z_mm: [0, 2], voxel_mm: 0.5}\n"
                                            "correlation: {passes: [{window: 4, overlap_percent: 50}]}\n") +
                                extra,
                            "run.yaml");
  }

  void wait_finished(daemon::Run& run) {
    for (int i = 0; i < 1000 && !run.finished(); ++i) std::this_thread::sleep_for(10ms);
    ASSERT_TRUE(run.finished());
  }

  static std::uint64_t recorded(const daemon::Run& run) {
    msg::Status s;
    run.fill_status(s);
    return s.pairs_recorded();
  }

  // The sim trigger's lines, as it reports them.
  static void expect_all_lines_low(const daemon::Run& run) {
    const auto* sim = dynamic_cast<const drivers::SimTrigger*>(&run.trigger());
    ASSERT_NE(sim, nullptr);
    for (drivers::TriggerLine line : drivers::kTriggerLines) {
      EXPECT_FALSE(sim->level(line)) << drivers::to_string(line);
    }
    EXPECT_FALSE(run.trigger().running());
  }

  // Every recorded pair carries the dt the sim trigger measured for its own shot (the sync stamps
  // of the Q-switches with its trigger index, exactly), next to the nominal one.
  static void expect_measured_dt(const msg::RunManifest& m, const daemon::Run& run, double dt_s) {
    const auto* sim = dynamic_cast<const drivers::SimTrigger*>(&run.trigger());
    ASSERT_NE(sim, nullptr);
    std::map<std::uint64_t, std::array<std::uint64_t, 2>> sync;  // shot -> sync stamps of Q1, Q2
    for (const drivers::RecordedEdge& e : sim->edges()) {
      if (!e.level) continue;
      if (e.line == drivers::TriggerLine::QSwitch1) sync[e.shot][0] = e.sync_ns;
      if (e.line == drivers::TriggerLine::QSwitch2) sync[e.shot][1] = e.sync_ns;
    }
    double worst = 0;
    ASSERT_GT(m.pairs_size(), 0);
    for (const msg::ManifestPair& p : m.pairs()) {
      EXPECT_DOUBLE_EQ(p.nominal_dt_s(), dt_s);
      EXPECT_GT(p.pulse1_ns(), 0u) << "pair " << p.pair_index();
      EXPECT_DOUBLE_EQ(p.measured_dt_s(), double(p.pulse2_ns() - p.pulse1_ns()) * 1e-9);
      // A pulse from another shot, or the other pulse of this one, has another stamp.
      ASSERT_EQ(sync.count(p.trigger_index()), 1u) << "pair " << p.pair_index();
      EXPECT_EQ(p.pulse1_ns(), sync.at(p.trigger_index())[0]) << "pair " << p.pair_index();
      EXPECT_EQ(p.pulse2_ns(), sync.at(p.trigger_index())[1]) << "pair " << p.pair_index();
      worst = std::max(worst, std::abs(p.measured_dt_s() - dt_s));
    }
    // The sim trigger writes each edge when its thread wakes, so the measured dt carries the
    // thread's wake-up jitter (Q-switch 1 written late makes dt short; a thread preempted between
    // the pulses: milliseconds). The bound is a quarter of the 100 ms period: a dt from the wrong
    // shot or the wrong clock fails it.
    std::printf("measured dt: worst |dt - nominal| %.1f us over %d pairs\n", worst * 1e6, m.pairs_size());
    EXPECT_LT(worst, 25e-3);
  }
  fs::path data_;
  RunStateMachine state_;
  RunEnvironment env_;
};

TEST_F(RunTest, RunOfNPairsRecordsAllAndEndsIdle) {
  state_.start("n");
  daemon::Run run(config("pairs: 6\nrate_hz: 50\ndt_s: 0.001\n"), "n", env_);
  wait_finished(run);
  EXPECT_EQ(state_.state(), RunState::Idle) << state_.error();
  const msg::RunManifest m = read_manifest(run.dir());
  EXPECT_EQ(m.state(), "complete");
  EXPECT_EQ(m.camera_triggering().rfind("external: camera line of sim://", 0), 0u) << m.camera_triggering();
  ASSERT_EQ(m.pairs_size(), 6);
  expect_measured_dt(m, run, 1e-3);
  expect_all_lines_low(run);
  EXPECT_EQ(run.trigger().counters().shots_fired, 6u);
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(m.pairs(i).pair_index(), std::uint64_t(i));
    EXPECT_EQ(m.pairs(i).trigger_index(), std::uint64_t(i));
    EXPECT_TRUE(fs::exists(run.dir() / m.pairs(i).frame_a()));
    EXPECT_TRUE(fs::exists(run.dir() / m.pairs(i).frame_b()));
  }
  EXPECT_EQ(m.pairs_processed() + m.pairs_skipped(), 6u);
  msg::Status s;
  run.fill_status(s);
  EXPECT_EQ(s.pairs_recorded(), 6u);
  EXPECT_EQ(s.stages_size(), 3);
}

// A run that records faster than a disk takes is told so before its first pair: the data
// directory's write rate is measured (only for runs that record at least 100 MB/s) and a warning
// names data_dir, both rates and the frames to be lost. The probe file stays for the next run.
TEST_F(RunTest, ARunFasterThanTheDiskIsToldBeforeItStarts) {
  const testing_support::CapturedLog log;
  const fs::path probe = data_ / io::kWriteProbeName;
  state_.start("slow");
  {
    daemon::Run run(config("pairs: 2\nrate_hz: 50\n"), "slow", env_);  // 64 x 48 px: 0.6 MB/s
    wait_finished(run);
  }
  EXPECT_FALSE(fs::exists(probe)) << "a run that records little is not probed";
  state_.start("fast");
  msg::Status status;
  msg::RunManifest manifest;
  {
    // 4096 x 4096 px, two 16-bit frames per pair at 200 Hz: 13.4 GB/s, beyond any disk's burst here.
    daemon::Run run(config("pairs: 1\nrate_hz: 200\ncamera_uri: test://?sensor=4096x4096\n"), "fast", env_);
    wait_finished(run);
    run.fill_status(status);
    manifest = read_manifest(run.dir());
  }
  std::vector<std::string> lines;
  for (const std::string& l : log.lines())
    if (l.find("data_dir") != std::string::npos && l.find("MB/s") != std::string::npos) lines.push_back(l);
  ASSERT_EQ(lines.size(), 1u) << "one probe, for the fast run";
  std::printf("%s\n", lines[0].c_str());
  const std::string said = "run fast: data_dir " + data_.string() + " took ";
  const auto at = lines[0].find(said);
  ASSERT_NE(at, std::string::npos) << lines[0];
  const double taken_mb_s = std::stod(lines[0].substr(at + said.size()));
  EXPECT_NE(lines[0].find("this run records 13422 MB/s (67.1 MB per pair at 200 Hz)"), std::string::npos) << lines[0];
  if (taken_mb_s < 13422) {
    // The operator's client sees it in status, and the run folder keeps it.
    EXPECT_NE(lines[0].find("[warning]"), std::string::npos) << lines[0];
    EXPECT_NE(lines[0].find("the recorder will fall behind and lose frames"), std::string::npos) << lines[0];
    ASSERT_EQ(status.warnings_size(), 1);
    EXPECT_NE(status.warnings(0).find("the recorder will fall behind and lose frames"), std::string::npos)
        << status.warnings(0);
    ASSERT_EQ(manifest.warnings_size(), 1);
    EXPECT_EQ(manifest.warnings(0), status.warnings(0));
  } else {  // a data directory in memory faster than the run: said, not warned
    EXPECT_NE(lines[0].find("[info]"), std::string::npos) << lines[0];
    EXPECT_EQ(status.warnings_size(), 0);
  }
  EXPECT_EQ(fs::file_size(probe), std::uintmax_t(256) << 20) << "kept for the next run";
}

// A disk with room for the run but not for the probe beside it: no probe is written, that is said,
// and the run records its pair. (A probe that fails anyway is removed: WriteRate in tests/io.)
TEST_F(RunTest, AWriteProbeThatDoesNotFitIsSaidAndLeavesTheRoomToTheRun) {
  testing_support::SmallTmpfs disk(data_ / "small-disk", 200);
  if (!disk.mounted()) GTEST_SKIP() << disk.why_not();
  env_.data_dir = disk.dir();
  const testing_support::CapturedLog log;
  state_.start("tight");
  std::uint64_t recorded = 0;
  {
    daemon::Run run(config("pairs: 1\nrate_hz: 200\ncamera_uri: test://?sensor=4096x4096\n"), "tight", env_);
    wait_finished(run);
    msg::Status s;
    run.fill_status(s);
    recorded = s.pairs_recorded();
  }
  std::string said, all;
  for (const std::string& l : log.lines()) {
    if (l.find("no room for a 256 MiB write probe beside this run's frames") != std::string::npos) said = l;
    all += l;
  }
  EXPECT_NE(said.find("whether the disk takes 13422 MB/s is not checked"), std::string::npos) << all;
  EXPECT_FALSE(fs::exists(disk.dir() / io::kWriteProbeName));
  EXPECT_EQ(recorded, 1u) << state_.error() << "\n" << all;
}

// A run is set up on its own thread while Armed (the processing's tables): status says so, and
// the folder does not exist yet; a stop then ends the run once the setup step returns, going Idle
// with nothing recorded and no folder made.
TEST_F(RunTest, AStopWhileArmedEndsTheRunWithNoFolder) {
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::atomic<bool> building{false};
  env_.processing = [&, released](const RunConfig&, const RunCalibration&, process::Tier, const SetupProgress&) {
    building = true;
    released.wait();  // the weight tables, as long as the test wants
    return ProcessFn([](const drivers::FramePair& pair, const PairSteps&) { return tagged_field(pair); });
  };
  state_.start("armed");
  daemon::Run run(config("pairs: 3\nrate_hz: 50\n"), "armed", env_);
  for (int i = 0; i < 500 && !building; ++i) std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(building);
  EXPECT_EQ(state_.state(), RunState::Armed);
  EXPECT_FALSE(fs::exists(run.dir())) << run.dir();
  msg::Status s;
  run.fill_status(s);
  EXPECT_EQ(s.run_id(), "armed");
  EXPECT_EQ(s.run_dir(), run.dir().string());
  EXPECT_EQ(s.message().rfind("setting up: processing and weight tables", 0), 0u) << s.message();
  state_.stop();  // what `run stop` does, in this order
  run.request_stop();
  EXPECT_EQ(state_.state(), RunState::Draining);
  release.set_value();
  wait_finished(run);
  EXPECT_EQ(state_.state(), RunState::Idle) << state_.error();
  EXPECT_FALSE(fs::exists(run.dir())) << run.dir();
  expect_all_lines_low(run);
  EXPECT_EQ(run.trigger().counters().shots_fired, 0u);
}

// A long setup step (a depth response measured) says how far it is in status, and a stop while
// Armed ends it at its next report: the run goes Idle with nothing recorded and no folder made.
TEST_F(RunTest, AStopEndsALongSetupStepAtItsNextReport) {
  std::atomic<int> reports{0};
  std::atomic<bool> cancelled{false};
  env_.processing = [&](const RunConfig&, const RunCalibration&, process::Tier,
                        const SetupProgress& progress) -> ProcessFn {
    try {
      for (int pair = 0; pair < 100000; ++pair) {  // far longer than the test waits
        progress("depth response of the full tier", 0.25);
        ++reports;
        std::this_thread::sleep_for(5ms);
      }
    } catch (const Cancelled&) {
      cancelled = true;
      throw;
    }
    ADD_FAILURE() << "the setup was not stopped";
    return ProcessFn([](const drivers::FramePair& pair, const PairSteps&) { return tagged_field(pair); });
  };
  state_.start("measuring");
  daemon::Run run(config("pairs: 3\nrate_hz: 50\n"), "measuring", env_);
  for (int i = 0; i < 500 && reports < 2; ++i) std::this_thread::sleep_for(10ms);
  ASSERT_GE(reports, 2);
  msg::Status s;
  run.fill_status(s);
  EXPECT_EQ(s.message().rfind("setting up: depth response of the full tier, 25 % measured, ", 0), 0u) << s.message();
  EXPECT_NE(s.message().find(" so far, about "), std::string::npos) << s.message();  // the step's time left
  EXPECT_FALSE(s.run_set_up());
  state_.stop();
  run.request_stop();
  wait_finished(run);
  EXPECT_TRUE(cancelled);
  EXPECT_EQ(state_.state(), RunState::Idle) << state_.error();
  EXPECT_FALSE(fs::exists(run.dir())) << run.dir();
  expect_all_lines_low(run);
  EXPECT_EQ(run.trigger().counters().shots_fired, 0u);
}

// Settings the processing refuses while the run is set up (after the start was answered) put the
// daemon into Error with the reason, and make no folder.
TEST_F(RunTest, ASetupFailureIsTheRunsErrorWithNoFolder) {
  env_.processing = [](const RunConfig&, const RunCalibration&, process::Tier, const SetupProgress&) -> ProcessFn {
    throw InputError("volume: z_mm: the box reaches behind the main lens");
  };
  state_.start("bad-setup");
  daemon::Run run(config("pairs: 3\nrate_hz: 50\n"), "bad-setup", env_);
  wait_finished(run);
  EXPECT_EQ(state_.state(), RunState::Error);
  EXPECT_EQ(state_.error(), "run bad-setup: setting up: volume: z_mm: the box reaches behind the main lens");
  EXPECT_FALSE(fs::exists(run.dir())) << run.dir();
  expect_all_lines_low(run);
}

TEST_F(RunTest, StopMidRunLeavesAConsistentFolder) {
  state_.start("s");
  daemon::Run run(config("pairs: 0\nrate_hz: 40\n"), "s", env_);
  // Stopped once a few pairs are in, however long a loaded machine takes to set the run up.
  for (int i = 0; i < 1000 && recorded(run) < 3; ++i) std::this_thread::sleep_for(10ms);
  ASSERT_GE(recorded(run), 3u);
  state_.stop();
  run.request_stop();
  wait_finished(run);
  EXPECT_EQ(state_.state(), RunState::Idle);
  const msg::RunManifest m = read_manifest(run.dir());
  EXPECT_EQ(m.state(), "stopped");
  EXPECT_GT(m.pairs_size(), 2);
  expect_all_lines_low(run);
  std::size_t frames = 0;
  for (const auto& e : fs::directory_iterator(run.dir() / "frames")) frames += e.is_regular_file();
  EXPECT_EQ(frames, std::size_t(2 * m.pairs_size()));  // every frame on disk is listed, and back
}

// A test camera that can be unplugged, and that is back inside the first status() call a chosen
// thread makes afterwards, once that call has read the connection as lost: the moment a status's
// two reads of the camera (its counters, its connection) could straddle.
class ReconnectsDuringStatus : public testing_support::TestCamera {
 public:
  using TestCamera::TestCamera;
  void unplug_until_asked_by(std::thread::id asker) {
    asker_ = asker;
    report_lost("cable pulled");
  }
  drivers::CameraStatus status() const override {
    const drivers::CameraStatus s = TestCamera::status();
    if (!s.connected && std::this_thread::get_id() == asker_.load()) {
      const_cast<ReconnectsDuringStatus*>(this)->plug_in();
    }
    return s;
  }

 private:
  void plug_in() {
    asker_ = std::thread::id{};
    report_reconnected();
  }
  std::atomic<std::thread::id> asker_{};
};

TEST_F(RunTest, AStatusCountsAReconnectOnlyWithoutTheOutageItEnded) {
  // Made on the run's set-up thread; shared with the registry, which outlives the test.
  const auto camera = std::make_shared<std::atomic<ReconnectsDuringStatus*>>(nullptr);
  drivers::CameraRegistry::instance().add("reconnecting", [camera](const drivers::DeviceUri& uri) {
    auto made = std::make_unique<ReconnectsDuringStatus>(uri.text());
    *camera = made.get();
    return std::unique_ptr<drivers::Camera>(std::move(made));
  });
  state_.start("r");
  daemon::Run run(config("pairs: 0\nrate_hz: 40\ncamera_uri: reconnecting://\n"), "r", env_);
  for (int i = 0; i < 1000 && recorded(run) < 2; ++i) std::this_thread::sleep_for(10ms);
  ASSERT_GE(recorded(run), 2u);
  ASSERT_NE(camera->load(), nullptr);
  // Lost when this status reads the connection, back before it could read the counters.
  camera->load()->unplug_until_asked_by(std::this_thread::get_id());
  msg::Status during;
  run.fill_status(during);
  EXPECT_NE(during.message().find("camera lost (cable pulled)"), std::string::npos) << during.DebugString();
  EXPECT_EQ(during.losses().camera_reconnects(), 0u) << "a status carries the outage and the reconnect that ended it";
  msg::Status after;
  run.fill_status(after);
  EXPECT_EQ(after.losses().camera_reconnects(), 1u) << after.DebugString();
  EXPECT_EQ(after.message().find("camera lost"), std::string::npos) << after.DebugString();
  state_.stop();
  run.request_stop();
  wait_finished(run);
  expect_all_lines_low(run);
}

TEST_F(RunTest, UnknownCameraIsAnInputErrorNamingTheUri) {
  RunConfig c = config("camera_uri: nosuch://x\n");
  try {
    daemon::Run run(c, "u", env_);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("nosuch://x"), std::string::npos) << e.what();
  }
}

// run.yaml's camera_roi reaches the camera, which refuses a region it cannot read out by name,
// before any folder is made (the simulated camera renders its whole sensor only).
TEST_F(RunTest, ACameraRegionTheCameraCannotReadIsRefusedByName) {
  drivers::register_sim_camera(drivers::CameraRegistry::instance(),
                               std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  RunConfig c = config("camera_uri: sim://?rays=100&ppm=0.02\ncamera_roi: {width: 64, height: 64}\n");
  try {
    daemon::Run run(c, "roi", env_);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("roi: the simulated camera renders the full sensor only"), std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(fs::exists(data_ / "run-roi"));
}

// Frames whose size differs from the camera file the processing reconstructs with (the camera's
// whole sensor, or its camera_roi) could be recorded but never processed: the run is refused at
// start, naming both sizes, before any folder is made. A region of the camera file's size starts.
TEST_F(RunTest, FramesOfAnotherSizeThanTheCameraFileAreRefusedAtStart) {
  const fs::path camera_file = data_.parent_path() / "camera-64x48.yaml";
  {
    std::ifstream small(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
    std::string text((std::istreambuf_iterator<char>(small)), std::istreambuf_iterator<char>());
    const std::string size = "width_px: 850, height_px: 850";
    ASSERT_NE(text.find(size), std::string::npos);
    text.replace(text.find(size), size.size(), "width_px: 48, height_px: 32");
    std::ofstream(camera_file) << text;
  }
  env_.camera_file = camera_file;
  env_.processing_reads_camera_file = true;
  for (const auto& [extra, culprit] :
       {std::pair<std::string, std::string>{"", "camera_uri test://: a sensor of 64 x 48 px"},
        {"camera_roi: {width: 40, height: 32}\n", "camera_roi: a region of 40 x 32 px"}}) {
    try {
      daemon::Run run(config(extra), "size", env_);
      ADD_FAILURE() << "started with " << extra;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(
          what.find(culprit + " does not match camera_file " + camera_file.string() + ", whose sensor is 48 x 32 px"),
          std::string::npos)
          << what;
    }
    EXPECT_FALSE(fs::exists(data_ / "run-size"));
  }
  state_.start("fits");
  daemon::Run run(config("pairs: 2\nrate_hz: 20\ncamera_roi: {width: 48, height: 32}\n"), "fits", env_);
  wait_finished(run);
  EXPECT_EQ(recorded(run), 2u);
}

// Frames that never arrive are counted by the gap they leave in the frame ids, which the run's
// last frames do not leave, and a trigger whose frames all went missing is counted but was not
// listed: the run counts and lists both against the triggers it made, so every frame the
// triggers made is a recorded or a lost one and every trigger a pair or a listed drop. Of 3 pairs
// (frames 0-5) the test camera loses the last B, the whole last pair, or the whole middle pair.
TEST_F(RunTest, FramesAndTriggersThatNeverArriveAreCountedAndListed) {
  struct Case {
    std::string lost, reason;
    std::uint64_t trigger;
  };
  for (const Case& c :
       {Case{"5", "unpaired frame", 2}, Case{"4,5", "never arrived", 2}, Case{"2,3", "never arrived", 1}}) {
    const std::string id = "lose-" + std::to_string(c.lost.size()) + "-" + std::to_string(c.trigger);
    state_.start(id);
    daemon::Run run(config("pairs: 3\nrate_hz: 20\ncamera_uri: test://?lose=" + c.lost + "\n"), id, env_);
    wait_finished(run);
    msg::Status s;
    run.fill_status(s);
    EXPECT_EQ(s.pairs_recorded(), 2u) << c.lost;
    EXPECT_EQ(2 * s.pairs_recorded() + s.frames_lost(), 6u) << c.lost << ": " << s.losses().ShortDebugString();
    const msg::RunManifest m = testing_support::read_manifest(run.dir());
    EXPECT_EQ(m.frames_lost(), s.frames_lost()) << c.lost;
    ASSERT_EQ(m.dropped_size(), 1) << c.lost << ": " << m.ShortDebugString();
    EXPECT_EQ(m.dropped(0).trigger_index(), c.trigger) << c.lost;
    EXPECT_EQ(m.dropped(0).reason(), c.reason) << c.lost;
  }
}

TEST_F(RunTest, UnknownTriggerIsAnInputErrorNamingTheUri) {
  RunConfig c = config("trigger_uri: nosuch://x\n");
  try {
    daemon::Run run(c, "t", env_);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("nosuch://x"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(data_ / "run-t"));
}

TEST_F(RunTest, ARateTheLaserCannotDoIsAnInputErrorBeforeAnythingIsRecorded) {
  env_.timing.limits = drivers::TimingLimits{};  // 15 Hz
  try {
    daemon::Run run(config("rate_hz: 40\n"), "r", env_);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("above the laser's maximum"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(data_ / "run-r"));
}

// The simulated camera renders a pair for each rising edge of the sim trigger's camera line.
TEST_F(RunTest, TheSimTriggersCameraLineFiresTheSimCamera) {
  drivers::register_sim_camera(drivers::CameraRegistry::instance(),
                               std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  constexpr int n = 4;
  state_.start("sim");
  daemon::Run run(config("camera_uri: sim://?rays=100&ppm=0.02\npairs: 4\nrate_hz: 10\ndt_s: 0.001\n"), "sim", env_);
  wait_finished(run);
  EXPECT_EQ(state_.state(), RunState::Idle) << state_.error();
  const msg::RunManifest m = read_manifest(run.dir());
  EXPECT_EQ(m.state(), "complete");
  EXPECT_EQ(m.camera_triggering().rfind("external: camera line of sim://", 0), 0u) << m.camera_triggering();
  ASSERT_EQ(m.pairs_size(), n);
  for (int i = 0; i < n; ++i) EXPECT_EQ(m.pairs(i).trigger_index(), std::uint64_t(i));
  expect_measured_dt(m, run, 1e-3);
  expect_all_lines_low(run);
  // One rising camera edge per pair made them: the camera had no other trigger.
  const auto* sim = dynamic_cast<const drivers::SimTrigger*>(&run.trigger());
  int camera_edges = 0;
  for (const drivers::RecordedEdge& e : sim->edges()) camera_edges += e.line == drivers::TriggerLine::Camera && e.level;
  EXPECT_EQ(camera_edges, n);
}

// A camera no trigger line can reach is fired by software, and the manifest says so.
TEST_F(RunTest, ACameraWithoutATriggerInputIsSoftwareTriggeredAndTheManifestSaysSo) {
  state_.start("sw");
  daemon::Run run(config("camera_uri: test://?input=none\npairs: 3\nrate_hz: 50\n"), "sw", env_);
  wait_finished(run);
  EXPECT_EQ(state_.state(), RunState::Idle) << state_.error();
  const msg::RunManifest m = read_manifest(run.dir());
  EXPECT_EQ(m.pairs_size(), 3);
  EXPECT_EQ(m.camera_triggering().rfind("software: ", 0), 0u) << m.camera_triggering();
  EXPECT_NE(m.camera_triggering().find("not synchronised"), std::string::npos);
  expect_all_lines_low(run);
}

// A stop is bounded however long the processing would take: pairs in flight give up at their next
// check (they stay on disk), the folder is closed "stopped" and says what was cancelled.
TEST_F(RunTest, AStopWithSlowProcessingInFlightIsBounded) {
  env_.processing = [](const RunConfig&, const RunCalibration&, process::Tier, const SetupProgress&) {
    return ProcessFn([](const drivers::FramePair& pair, const PairSteps& steps) {
      for (int iteration = 0; iteration < 6000; ++iteration) {  // a minute of "MART iterations"
        steps.step();
        std::this_thread::sleep_for(10ms);
      }
      return tagged_field(pair);
    });
  };
  state_.start("slow");
  daemon::Run run(config("pairs: 0\nrate_hz: 20\nmax_pairs_in_flight: 2\nlive_queue: 3\n"), "slow", env_);
  for (int i = 0; i < 500 && recorded(run) < 10; ++i) std::this_thread::sleep_for(10ms);
  const auto stop = std::chrono::steady_clock::now();
  state_.stop();
  run.request_stop();
  wait_finished(run);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - stop).count();
  EXPECT_LT(took, 10.0) << "the stop waited for the processing";
  EXPECT_EQ(state_.state(), RunState::Idle) << state_.error();
  const msg::RunManifest m = read_manifest(run.dir());
  EXPECT_EQ(m.state(), "stopped");
  EXPECT_GE(m.pairs_size(), 10);
  EXPECT_EQ(m.pairs_processed(), 0u);
  EXPECT_GE(m.losses().processing_cancelled(), 1u);
  // Every recorded pair was processed, cancelled, or dropped from the bounded live queue.
  EXPECT_EQ(m.losses().processing_cancelled() + m.losses().live_queue_dropped(), std::uint64_t(m.pairs_size()))
      << m.losses().DebugString();
  EXPECT_EQ(m.frames_lost(), 0u);
  expect_all_lines_low(run);
}

TEST_F(RunTest, ATooSlowOrNotANumberRateIsRefusedBeforeAnythingFires) {
  state_.start("rate");
  for (const char* rate : {"1e-12", ".nan"}) {
    try {
      daemon::Run run(config(std::string("pairs: 3\nrate_hz: ") + rate + "\n"), "rate", env_);
      ADD_FAILURE() << "rate_hz " << rate << " was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("rate"), std::string::npos) << e.what();
    }
  }
  state_.cancel_start();
  EXPECT_FALSE(fs::exists(data_ / "run-rate"));
}

// A field with its uncertainty goes out with sigma_u, sigma_v, sigma_w named after u, v, w, valid
// and in m/s like them (NaN where a vector has none); one without it names only the four.
TEST(Publisher, TheUncertaintyIsPublishedAsNamedPayloads) {
  zmq::context_t context;
  Publisher publisher(context, "tcp://127.0.0.1:*", 10);
  zmq::socket_t sub(context, zmq::socket_type::sub);
  sub.set(zmq::sockopt::subscribe, "vectors");
  sub.set(zmq::sockopt::rcvtimeo, 5000);
  sub.connect(publisher.endpoint());
  Grid3 g;
  g.shape = {3, 2, 2};
  VectorField f(g);
  f.dt_s = 1e-3;
  f.dx_mm.assign(g.count(), 0.5f);
  f.valid.assign(g.count(), 1);
  for (auto* s : {&f.sigma_dx_mm, &f.sigma_dy_mm, &f.sigma_dz_mm}) s->assign(g.count(), 0.004f);
  f.sigma_dz_mm[5] = NAN;
  f.sigma_method = "correlation statistics of the final pass";
  VectorField plain = f;
  plain.sigma_dx_mm.clear();
  plain.sigma_dy_mm.clear();
  plain.sigma_dz_mm.clear();
  // PUB drops what is sent before the subscription arrives: send until a message comes.
  std::vector<zmq::message_t> parts;
  for (int attempt = 0; attempt < 50 && parts.empty(); ++attempt) {
    publisher.publish_vectors({}, f);
    std::this_thread::sleep_for(50ms);
    zmq::message_t m;
    while (sub.recv(m, zmq::recv_flags::dontwait)) {
      parts.push_back(std::move(m));
      if (!parts.back().more()) break;
    }
  }
  ASSERT_EQ(parts.size(), 9u);  // topic, header, 7 arrays
  msg::VectorFieldHeader header;
  ASSERT_TRUE(header.ParseFromArray(parts[1].data(), int(parts[1].size())));
  std::vector<std::string> names(header.payloads().begin(), header.payloads().end());
  EXPECT_EQ(names, (std::vector<std::string>{"u", "v", "w", "valid", "sigma_u", "sigma_v", "sigma_w"}));
  EXPECT_EQ(header.sigma_method(), f.sigma_method);  // what the sigma payloads hold
  // A ZeroMQ frame's bytes need not be aligned for float: copied out.
  const auto floats = [](const zmq::message_t& frame) {
    std::vector<float> out(frame.size() / sizeof(float));
    std::memcpy(out.data(), frame.data(), out.size() * sizeof(float));
    return out;
  };
  const std::vector<float> sigma_u = floats(parts[6]);
  const std::vector<float> sigma_w = floats(parts[8]);
  ASSERT_GT(sigma_w.size(), 5u);
  EXPECT_FLOAT_EQ(sigma_u[0], 0.004f);  // 0.004 mm in 1 ms: 4 mm/s
  EXPECT_TRUE(std::isnan(sigma_w[5]));
  // Drain, then the field without an uncertainty.
  zmq::message_t m;
  while (sub.recv(m, zmq::recv_flags::dontwait)) {
  }
  publisher.publish_vectors({}, plain);
  std::vector<zmq::message_t> plain_parts;
  do {
    ASSERT_TRUE(sub.recv(m));
    plain_parts.push_back(std::move(m));
  } while (plain_parts.back().more());
  ASSERT_TRUE(header.ParseFromArray(plain_parts[1].data(), int(plain_parts[1].size())));
  EXPECT_EQ(header.payloads_size(), 4);
  EXPECT_EQ(plain_parts.size(), 6u);
}

TEST_F(RunTest, ASubscriberThatNeverReadsDoesNotSlowAcquisition) {
  zmq::context_t context;
  auto publisher = std::make_optional<Publisher>(context, "tcp://127.0.0.1:*", 2);
  env_.publisher = &*publisher;
  // Big fields (32^3 nodes, 4 arrays: 512 KiB a message) fill the socket buffers quickly.
  env_.processing = [](const RunConfig&, const RunCalibration&, process::Tier, const SetupProgress&) {
    return ProcessFn([](const drivers::FramePair& pair, const PairSteps&) {
      Grid3 g;
      g.shape = {32, 32, 32};
      ProcessedPair out;
      out.vectors = VectorField(g);
      out.vectors.dt_s = 1e-3;
      out.vectors.dx_mm.assign(g.count(), float(pair.pair_index));
      return out;
    });
  };
  zmq::socket_t deaf(context, zmq::socket_type::sub);
  deaf.set(zmq::sockopt::rcvhwm, 1);
  deaf.set(zmq::sockopt::subscribe, "");
  deaf.connect(publisher->endpoint());
  std::this_thread::sleep_for(100ms);  // let the subscription reach the publisher

  const auto start = std::chrono::steady_clock::now();
  state_.start("deaf");
  daemon::Run run(config("pairs: 40\nrate_hz: 20\nmax_pairs_in_flight: 2\n"), "deaf", env_);
  wait_finished(run);
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const msg::RunManifest m = read_manifest(run.dir());
  EXPECT_EQ(m.pairs_size(), 40);  // raw frame count unchanged
  EXPECT_EQ(m.pairs_processed() + m.pairs_skipped(), 40u);
  EXPECT_GE(publisher->messages_sent(), m.pairs_processed());  // every send returned
  // 40 pairs at 20 Hz take 2 s; a publisher that blocked on the deaf subscriber would never
  // finish. A bound on hanging, not a timing figure.
  EXPECT_LT(elapsed, 10.0);

  // The subscriber leaves first and the publisher closes once it has seen it go. libzmq 4.3.4
  // aborts with "Resource temporarily unavailable (src/session_base.cpp:260)" when a peer drops
  // while a linger-0 PUB socket is closing half-way through a multipart message to it (its
  // session_base_t::clean_pipes cannot read the rest from a terminating pipe): closing both at
  // once did so in about 1 run in 8, publisher first in 1 in 5.
  deaf.close();
  std::this_thread::sleep_for(300ms);
  env_.publisher = nullptr;
  publisher.reset();
}

}  // namespace
}  // namespace plenopiv::daemon
