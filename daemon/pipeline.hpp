// The live path: a bounded tbb::parallel_pipeline from recorded pairs to published vector fields.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/base/grid.hpp"
#include "drivers/camera/camera.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::daemon {

using SharedPair = std::shared_ptr<const drivers::FramePair>;

// What MART left alone on a pair (both frames), for the status and the log.
struct ReconstructionWork {
  std::size_t voxels = 0;                       // in the reconstructed box
  std::vector<std::size_t> live_a, live_b;      // voxels each iteration updated, frames A and B
  double updates_skipped = 0;                   // share of the box's voxel updates not done
  double work_pruned = 0;                       // share of the kernels' work pruning saved
  double black_level_a = 0, black_level_b = 0;  // counts taken off each frame first: the median over its tiles
  // Each frame's lowest and highest tile's level (process::BlackLevels).
  double black_level_a_lowest = 0, black_level_a_highest = 0, black_level_b_lowest = 0, black_level_b_highest = 0;
};

// What the processing stage makes of a pair.
struct ProcessedPair {
  VectorField vectors;
  std::vector<std::uint8_t> flags;           // the correlation's VectorFlag bits per node (none: not known)
  std::optional<Volume> volume_a, volume_b;  // when the run publishes volumes
  std::optional<ReconstructionWork> work;    // when the stage reconstructs (plenoptic_processing)
};

// Set when the run stops: processing in flight gives up (plenopiv::Cancelled) at its next MART
// iteration or correlation pass.
using CancelFlag = std::atomic<bool>;

// Where a lane of lower priority waits, between the steps of its pairs, while a lane of higher
// priority is busy (a pair in flight or waiting in its queue), so that the higher one gets every
// core: niceness weighs threads only on one CPU's run queue and cannot keep a busy low-priority
// thread off a core of its own (bench_lanes paper, docs/benchmarks.md). Thread safe.
class PriorityGate {
 public:
  // Sets whether the higher-priority lane is busy to what `busy_now` says, called under the gate's
  // lock, so that of concurrent callers the last leaves the latest state. The lane calls it
  // whenever what it depends on changes.
  void reassess(const std::function<bool()>& busy_now);
  // Returns once the higher-priority lane is not busy or `cancel` is set; the time it waited.
  std::chrono::steady_clock::duration wait_turn(const CancelFlag& cancel) const;

 private:
  mutable std::mutex mutex_;
  mutable std::condition_variable free_;
  bool busy_ = false;
};

// How far a long step is, as the status says it: "40 % measured, 2 min so far, about 3 min left"
// (`fraction` 0..1 of the step done in `elapsed_s`; the time left at the pace so far, once under
// way and not done; seconds up to a minute and a half, minutes beyond).
std::string measured_so_far(double fraction, double elapsed_s);

// What a processing stage's pair in flight does beyond processing, for the status: a step of the
// lane's set-up its first pair takes (a deferred depth response), said by PairSteps::say and
// cleared when the pair ends; empty otherwise. One text per stage (the quality lane has one pair in
// flight; of several, the last said). Thread safe.
class StageActivity {
 public:
  void set(std::string text);
  std::string text() const;

 private:
  mutable std::mutex mutex_;
  std::string text_;
};

// What processing does at each step of a pair (as it starts, and after every MART iteration and
// correlation pass): first wait while the lane above it (`yield_to`, none for the live lane) is
// busy, then give up (plenopiv::Cancelled) once the run stops.
class PairSteps {
 public:
  explicit PairSteps(const CancelFlag& cancel, const PriorityGate* yield_to = nullptr,
                     StageActivity* activity = nullptr)
      : cancel_(cancel), yield_to_(yield_to), activity_(activity) {}
  void step() const;
  // What the pair is doing beyond processing, shown in the status until the pair ends.
  void say(std::string text) const {
    if (activity_) activity_->set(std::move(text));
  }
  // The time spent waiting at the gate, not processing.
  std::chrono::steady_clock::duration waited() const { return waited_; }

 private:
  const CancelFlag& cancel_;
  const PriorityGate* yield_to_;
  StageActivity* activity_;
  mutable std::chrono::steady_clock::duration waited_{};
};

// The processing stage: preprocess, reconstruct A and B, correlate. Called concurrently for
// different pairs; it must not keep state between calls except read-only setup. It calls
// `steps.step()` as it goes, which throws plenopiv::Cancelled once the run stops.
using ProcessFn = std::function<ProcessedPair(const drivers::FramePair&, const PairSteps& steps)>;

// Which waiting pair a lane's queue hands out.
enum class TakeOrder {
  newest,  // the newest; the older ones are dropped (counted): the operator sees the latest pair
  oldest,  // the oldest: pairs are processed in order while the lane keeps up
};

// Pairs recorded and waiting for a processing lane: at most `capacity`. The acquisition side pushes
// the recorded pairs the lane takes; a push into a full queue drops the oldest waiting pair, and
// take() hands out one pair in `order` (TakeOrder::newest drops the older ones); either way the
// dropped pairs are counted (they are on disk already). Memory stays bounded whatever the laser
// rate. Thread safe.
class LiveMailbox {
 public:
  explicit LiveMailbox(std::size_t capacity = 2, TakeOrder order = TakeOrder::newest)
      : capacity_(std::max<std::size_t>(capacity, 1)), order_(order) {}
  void push(SharedPair pair);
  void close();  // no more pairs: take() returns nullopt once empty
  // close() and forget what is waiting (a stop: the pairs are recorded, none is processed now).
  void close_and_clear();
  // Blocks until a pair or close. Returns the newest or oldest pair, as the queue's order says.
  std::optional<SharedPair> take();
  // take() without waiting: nullopt when no pair is waiting, and then `closed` says whether one
  // ever will be.
  std::optional<SharedPair> try_take(bool& closed);
  // Calls `wake` once a pair can be taken or the queue is closed: at once on this thread if that
  // is so already, else on the thread of the push or close that makes it so. One waiter at a time
  // (a later call replaces a waiter not yet woken).
  void call_when_ready(std::function<void()> wake);
  // Waits up to `timeout` for close(); true once closed.
  bool wait_closed_for(std::chrono::steady_clock::duration timeout);
  std::size_t capacity() const { return capacity_; }
  std::size_t depth() const;
  std::uint64_t pushed() const;   // pairs ever pushed
  std::uint64_t dropped() const;  // pairs that left without being taken

 private:
  std::optional<SharedPair> take_locked();
  // The waiter to wake, taken under the lock when a pair or close makes it due.
  std::function<void()> due_waiter_locked();

  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::function<void()> waiter_;
  std::deque<SharedPair> pairs_;
  std::size_t capacity_;
  TakeOrder order_;
  std::uint64_t pushed_ = 0;
  std::uint64_t dropped_ = 0;
  bool closed_ = false;
};

// Per-stage counters, updated by the stages, read by status at any time.
struct StageStats {
  std::atomic<std::uint64_t> processed{0};
  std::atomic<std::uint64_t> skipped{0};    // processing threw: the pair stays on disk
  std::atomic<std::uint64_t> cancelled{0};  // in flight when the run stopped
  std::atomic<std::uint64_t> busy_ns{0};
  std::atomic<std::uint64_t> waited_ns{0};  // at a PriorityGate, not counted in busy_ns
  std::atomic<std::uint32_t> in_flight{0};
  void add_time(std::chrono::steady_clock::duration d) {
    busy_ns += std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(d).count());
  }
  void add_wait(std::chrono::steady_clock::duration d) {
    waited_ns += std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(d).count());
  }
  msg::StageCounters to_message(const char* name, std::uint32_t queue_depth, std::uint64_t dropped = 0) const;
};

struct PipelineStats {
  StageStats input, process, output;
  StageActivity activity;  // the processing stage's pair in flight (PairSteps::say)
};

// Output of the last (serial, in order) stage: publish and accumulate statistics.
using OutputFn = std::function<void(const drivers::FramePair&, ProcessedPair&)>;

// Runs until the mailbox is closed and empty. At most `max_in_flight` pairs are between input
// and output at once; output sees pairs in increasing pair order. While the mailbox is empty the
// stage waiting for it is suspended (oneTBB resumable tasks), so its thread works on the pairs in
// flight instead of blocking: a lane that waits for the camera holds no core. A pair whose processing throws
// is counted as skipped on the processing stage and not output; the run goes on. Once `cancel` is
// set, pairs in flight give up (counted cancelled); those already done are still output. With
// `yield_to`, each pair waits at it as it starts and between its steps (PairSteps); the time
// waited is not counted as processing time.
void run_live_pipeline(LiveMailbox& mailbox, int max_in_flight, const ProcessFn& process, const OutputFn& output,
                       PipelineStats& stats, const CancelFlag& cancel, const PriorityGate* yield_to = nullptr);

}  // namespace plenopiv::daemon
