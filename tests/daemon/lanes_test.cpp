// A run's lanes in-process: which pairs a lane is offered, the order it takes them in, its bounded
// queue and counters, and the lanes a run config makes.
#include <gtest/gtest.h>
#include <tbb/info.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <mutex>
#include <set>
#include <thread>

#include "daemon/lanes.hpp"
#include "daemon/thread_priority.hpp"

namespace plenopiv::daemon {
namespace {

SharedPair pair_of(std::uint64_t index) {
  auto p = std::make_shared<drivers::FramePair>();
  p->pair_index = index;
  p->trigger_index = index;
  return p;
}

ProcessedPair empty_field(const drivers::FramePair&, const PairSteps&) {
  ProcessedPair out;
  Grid3 g;
  g.shape = {1, 1, 1};
  out.vectors = VectorField(g);
  return out;
}

// A ProcessFn whose pair is a parallel loop of busy work (256 iterations of 20 000 additions);
// `seen` runs in every iteration, under one lock.
ProcessFn busy_pairs(std::mutex& m, const std::function<void()>& seen) {
  return [&m, seen](const drivers::FramePair& pair, const PairSteps& steps) {
    tbb::parallel_for(0, 256, [&](int) {
      volatile double x = 0;
      for (int i = 0; i < 20000; ++i) x = x + 1.0;
      std::lock_guard lock(m);
      seen();
    });
    return empty_field(pair, steps);
  };
}

TEST(Lane, EveryNthLaneIsOfferedTheMultiplesAndTakesThemOldestFirst) {
  Lane::Options o;
  o.name = "quality";
  o.order = TakeOrder::oldest;
  o.every = 3;
  o.capacity = 8;
  Lane lane(o);
  for (std::uint64_t i = 0; i < 10; ++i) lane.offer(pair_of(i));
  lane.close(false);
  std::vector<std::uint64_t> seen;
  CancelFlag cancel{false};
  lane.run(
      empty_field, [&](const drivers::FramePair& p, ProcessedPair&) { seen.push_back(p.pair_index); }, cancel);
  EXPECT_EQ(seen, (std::vector<std::uint64_t>{0, 3, 6, 9}));
  const msg::LaneCounters c = lane.counters();
  EXPECT_EQ(c.offered(), 4u);
  EXPECT_EQ(c.processed(), 4u);
  EXPECT_EQ(c.dropped(), 0u);
}

TEST(Lane, AFullQueueDropsItsOldestPairAndCountsIt) {
  Lane::Options o;
  o.name = "quality";
  o.order = TakeOrder::oldest;
  o.capacity = 3;
  Lane lane(o);
  for (std::uint64_t i = 0; i < 10; ++i) {
    lane.offer(pair_of(i));
    EXPECT_LE(lane.queue().depth(), 3u);
  }
  lane.close(false);
  std::vector<std::uint64_t> seen;
  CancelFlag cancel{false};
  lane.run(
      empty_field, [&](const drivers::FramePair& p, ProcessedPair&) { seen.push_back(p.pair_index); }, cancel);
  EXPECT_EQ(seen, (std::vector<std::uint64_t>{7, 8, 9}));  // the newest three stayed, in order
  const msg::LaneCounters c = lane.counters();
  EXPECT_EQ(c.offered(), 10u);
  EXPECT_EQ(c.dropped(), 7u);
  EXPECT_EQ(c.queue_capacity(), 3u);
  EXPECT_EQ(lane.skipped(), 7u);
}

TEST(Lane, AStopClearsTheQueueAndCountsWhatWasWaiting) {
  Lane lane(Lane::Options{});
  lane.offer(pair_of(0));
  lane.offer(pair_of(1));
  lane.close(true);
  lane.discard_all();
  EXPECT_EQ(lane.counters().dropped(), 2u);
  EXPECT_EQ(lane.counters().processed(), 0u);
}

// The recording thread offers pairs at its own priority; every thread that processes them (the
// lane's own, and oneTBB's workers in a parallel loop) runs at the lane's niceness.
TEST(Lane, ItsProcessingThreadsRunNicerThanTheRecordingThread) {
  const int recording = this_thread_niceness();
  if (recording > 14) GTEST_SKIP() << "the test runs at niceness " << recording << ": no room to lower it by 5";
  Lane::Options o;
  o.nice = recording + 5;
  o.order = TakeOrder::oldest;
  o.capacity = 4;
  Lane lane(o);
  std::mutex m;
  std::set<std::thread::id> threads;
  std::set<int> niceness;
  const ProcessFn process = busy_pairs(m, [&] {
    threads.insert(std::this_thread::get_id());
    niceness.insert(this_thread_niceness());
  });
  for (std::uint64_t i = 0; i < 4; ++i) lane.offer(pair_of(i));
  lane.close(false);
  int lane_thread = -1;
  CancelFlag cancel{false};
  std::thread runner([&] {
    lane.run(
        process, [](const drivers::FramePair&, ProcessedPair&) {}, cancel);
    lane_thread = this_thread_niceness();
  });
  runner.join();
  EXPECT_EQ(lane.counters().processed(), 4u);
  EXPECT_FALSE(threads.empty());
  EXPECT_EQ(niceness, std::set<int>{recording + 5});
  EXPECT_EQ(lane_thread, recording + 5) << "the thread that ran the lane";
  EXPECT_EQ(this_thread_niceness(), recording) << "the recording thread keeps its priority";
}

// A lane waiting for its next pair holds no oneTBB worker: while the recording offers pairs slower
// than they are processed (the queue empty between them), each pair's parallel loops still get
// every core.
TEST(Lane, AWaitingLaneLeavesEveryCoreToItsWork) {
  const int cores = tbb::this_task_arena::max_concurrency();
  if (cores < 2) GTEST_SKIP() << "one core: nothing to share";
  Lane::Options o;
  o.order = TakeOrder::oldest;
  o.capacity = 8;
  o.max_in_flight = 2;
  Lane lane(o);
  std::mutex m;
  std::vector<std::size_t> threads_per_pair;
  const auto process = [&](const drivers::FramePair& pair, const PairSteps& steps) {
    std::mutex seen_mutex;
    std::set<std::thread::id> seen;
    tbb::parallel_for(0, 64, [&](int) {
      const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(4);
      while (std::chrono::steady_clock::now() < until) {
      }
      std::lock_guard lock(seen_mutex);
      seen.insert(std::this_thread::get_id());
    });
    std::lock_guard lock(m);
    threads_per_pair.push_back(seen.size());
    return empty_field(pair, steps);
  };
  CancelFlag cancel{false};
  std::thread runner([&] {
    lane.run(
        process, [](const drivers::FramePair&, ProcessedPair&) {}, cancel);
  });
  for (std::uint64_t i = 0; i < 6; ++i) {
    // Each pair comes once the one before is done (the lane waiting, its queue empty).
    for (auto t0 = std::chrono::steady_clock::now();
         std::chrono::steady_clock::now() - t0 < std::chrono::seconds(30);) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      std::lock_guard lock(m);
      if (threads_per_pair.size() == i) break;
    }
    lane.offer(pair_of(i));
  }
  lane.close(false);
  runner.join();
  ASSERT_EQ(threads_per_pair.size(), 6u);
  // Every pair could use both cores, but a loaded machine (or workers left niced by another test)
  // may not give a worker time during some pairs' 0.25 s loops. A lane whose wait holds the worker
  // runs all but the last pair's loop on one thread.
  const auto shared =
      std::count_if(threads_per_pair.begin(), threads_per_pair.end() - 1, [](std::size_t n) { return n >= 2; });
  EXPECT_GE(shared, 2) << "the pairs' loops ran on one thread: the lane's wait held the other cores";
}

// What the lane's pair in flight says it does (a deferred depth response) is in the lane's
// counters, the status's, until the pair ends.
TEST(Lane, ItsCountersSayWhatItsPairInFlightDoes) {
  Lane lane(Lane::Options{});
  std::atomic<bool> said{false}, release{false};
  const auto process = [&](const drivers::FramePair& pair, const PairSteps& steps) {
    steps.say("depth response of the full tier, 40 % measured");
    said = true;
    while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    return empty_field(pair, steps);
  };
  CancelFlag cancel{false};
  std::thread runner([&] {
    lane.run(
        process, [](const drivers::FramePair&, ProcessedPair&) {}, cancel);
  });
  EXPECT_EQ(lane.counters().activity(), "");
  lane.offer(pair_of(0));
  while (!said) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(lane.counters().activity(), "depth response of the full tier, 40 % measured");
  EXPECT_EQ(lane.counters().in_flight(), 1u);
  release = true;
  lane.close(false);
  runner.join();
  EXPECT_EQ(lane.counters().processed(), 1u);
  EXPECT_EQ(lane.counters().activity(), "");
}

TEST(Lane, ARunConfigMakesTheLiveLaneFirstAndTheQualityLaneWhenAsked) {
  const std::string spec =
      "dt_s: 0.001\nvolume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 2], voxel_mm: 0.5}\n"
      "correlation: {passes: [{window: 4, overlap_percent: 50}]}\nlive_queue: 3\nmax_pairs_in_flight: 2\n";
  const auto one = make_lanes(parse_run_config(spec, "run.yaml"));
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0]->name(), "live");
  EXPECT_EQ(one[0]->tier(), process::Tier::full);
  EXPECT_EQ(one[0]->queue().capacity(), 3u);
  const auto two = make_lanes(parse_run_config(
      spec + "live: {reconstruction: {iterations: 1}}\nquality: {every: 2}\nquality_queue: 5\n", "run.yaml"));
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(two[0]->tier(), process::Tier::live);
  EXPECT_EQ(two[1]->name(), "quality");
  EXPECT_EQ(two[1]->tier(), process::Tier::full);
  EXPECT_EQ(two[1]->queue().capacity(), 5u);
  EXPECT_EQ(two[1]->counters().policy(), "every 2");
}

// Polls `done` every 5 ms for up to 30 s; true once it holds.
bool eventually(const std::function<bool()>& done) {
  for (auto t0 = std::chrono::steady_clock::now(); std::chrono::steady_clock::now() - t0 < std::chrono::seconds(30);) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return done();
}

// The quality lane's pairs wait while the live lane has a pair in flight or waiting: one about to
// start does not start, one in progress stops at its next step, and both go on once the live lane
// has nothing to do. The time waited is not counted as processing time, and a stop ends a wait.
TEST(Lane, TheQualityLaneWaitsBetweenItsStepsWhileTheLiveLaneHasAPair) {
  const std::string spec =
      "dt_s: 0.001\nvolume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 2], voxel_mm: 0.5}\n"
      "correlation: {passes: [{window: 4, overlap_percent: 50}]}\n"
      "live: {reconstruction: {iterations: 1}}\nquality: {every: 1}\nquality_queue: 8\n";
  const auto lanes = make_lanes(parse_run_config(spec, "run.yaml"));
  ASSERT_EQ(lanes.size(), 2u);
  Lane& live = *lanes[0];
  Lane& quality = *lanes[1];
  std::atomic<int> live_started{0}, live_released{0}, quality_steps{0};
  std::atomic<bool> quality_may_go_on{true};
  const ProcessFn live_process = [&](const drivers::FramePair& pair, const PairSteps& steps) {
    const int n = ++live_started;
    while (live_released < n) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    return empty_field(pair, steps);
  };
  // Ten steps, each followed by a hold while the test says so (quality_may_go_on false).
  const ProcessFn quality_process = [&](const drivers::FramePair& pair, const PairSteps& steps) {
    for (int step = 0; step < 10; ++step) {
      steps.step();
      ++quality_steps;
      while (!quality_may_go_on) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return empty_field(pair, steps);
  };
  CancelFlag cancel{false};
  std::thread live_runner([&] {
    live.run(
        live_process, [](const drivers::FramePair&, ProcessedPair&) {}, cancel);
  });
  std::thread quality_runner([&] {
    quality.run(
        quality_process, [](const drivers::FramePair&, ProcessedPair&) {}, cancel);
  });
  // Ends both lanes, also when an assertion below returns early.
  const std::function<void()> finish = [&] {
    cancel = true;
    live_released = 1000;
    quality_may_go_on = true;
    live.close(true);
    quality.close(true);
    if (live_runner.joinable()) live_runner.join();
    if (quality_runner.joinable()) quality_runner.join();
  };
  struct Finally {
    const std::function<void()>& f;
    ~Finally() { f(); }
  } finally{finish};

  // A live pair in flight and one waiting: the quality pair offered now does not start, nor
  // between the two live pairs.
  live.offer(pair_of(0));
  ASSERT_TRUE(eventually([&] { return live_started == 1; }));
  live.offer(pair_of(1));
  quality.offer(pair_of(0));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(quality_steps, 0) << "the quality pair started beside a live pair";
  ++live_released;
  ASSERT_TRUE(eventually([&] { return live_started == 2; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_EQ(quality_steps, 0) << "the quality pair started with a live pair waiting";
  ++live_released;
  ASSERT_TRUE(eventually([&] { return quality.counters().processed() == 1; }));
  EXPECT_EQ(quality_steps, 10);
  EXPECT_LT(quality.counters().mean_time_s(), 0.2) << "the 0.4 s waited counted as processing";
  // The hold lasts at least 0.4 s from the offer; the lane's clock starts when its thread
  // wakes, which on a loaded machine can be tens of milliseconds later.
  EXPECT_GE(quality.counters().waited_s(), 0.3);
  EXPECT_EQ(live.counters().waited_s(), 0.0);

  // A quality pair in progress stops at its next step while a live pair is in flight.
  quality_may_go_on = false;
  quality.offer(pair_of(1));
  ASSERT_TRUE(eventually([&] { return quality_steps == 11; }));
  live.offer(pair_of(2));
  ASSERT_TRUE(eventually([&] { return live_started == 3; }));
  quality_may_go_on = true;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(quality_steps, 11) << "the quality pair went on beside a live pair";
  ++live_released;
  ASSERT_TRUE(eventually([&] { return quality.counters().processed() == 2; }));
  EXPECT_EQ(quality_steps, 20);

  // A stop ends a wait: the waiting quality pair is cancelled, not held until the live pair ends.
  live.offer(pair_of(3));
  ASSERT_TRUE(eventually([&] { return live_started == 4; }));
  quality.offer(pair_of(2));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  cancel = true;
  EXPECT_TRUE(eventually([&] { return quality.counters().cancelled() == 1; }));
  EXPECT_EQ(quality_steps, 20);
  ++live_released;
  ASSERT_TRUE(eventually([&] { return live.counters().processed() == 4; })) << "the live lane's own pairs never wait";
}

// The quality lane runs behind the live lane at the kernel's level too: its own thread at the
// lowest priority, and its arena one thread short of the cores, so that a oneTBB worker stays free
// for the live lane (a worker that served the quality lane would keep its niceness). Its workers,
// where there are any (more than 2 cores), run at the processing niceness like the live lane's.
TEST(Lane, TheQualityLaneRunsAtTheLowestPriorityAndLeavesTheLiveLaneAWorker) {
  const int recording = this_thread_niceness();
  if (recording > 14) GTEST_SKIP() << "the test runs at niceness " << recording << ": no room to lower it by 5";
  const std::string spec =
      "dt_s: 0.001\nvolume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 2], voxel_mm: 0.5}\n"
      "correlation: {passes: [{window: 4, overlap_percent: 50}]}\n"
      "live: {reconstruction: {iterations: 1}}\nquality: {every: 1}\nquality_queue: 8\n";
  const auto lanes = make_lanes(parse_run_config(spec, "run.yaml"), recording + 5);
  ASSERT_EQ(lanes.size(), 2u);
  Lane& quality = *lanes[1];
  std::mutex m;
  std::set<std::thread::id> threads;
  std::set<int> worker_niceness;
  std::thread::id caller;
  const ProcessFn process = busy_pairs(m, [&] {
    threads.insert(std::this_thread::get_id());
    if (std::this_thread::get_id() != caller) worker_niceness.insert(this_thread_niceness());
  });
  for (std::uint64_t i = 0; i < 4; ++i) quality.offer(pair_of(i));
  quality.close(false);
  int caller_niceness = -1;
  CancelFlag cancel{false};
  std::thread runner([&] {
    caller = std::this_thread::get_id();
    quality.run(
        process, [](const drivers::FramePair&, ProcessedPair&) {}, cancel);
    caller_niceness = this_thread_niceness();
  });
  runner.join();
  EXPECT_EQ(quality.counters().processed(), 4u);
  EXPECT_EQ(caller_niceness, kQualityLaneNice) << "the quality lane's own thread";
  const int cores = tbb::info::default_concurrency();
  EXPECT_LE(int(threads.size()), std::max(1, cores - 1)) << "threads in the quality lane's loops";
  for (int n : worker_niceness) EXPECT_EQ(n, recording + 5) << "a worker in the quality lane";
  EXPECT_EQ(this_thread_niceness(), recording) << "the recording thread keeps its priority";
}

}  // namespace
}  // namespace plenopiv::daemon
