// A run's processing lanes: the live lane (every pair it can, fast tier, first call on the cores)
// and the quality lane (the full settings behind it), each a bounded queue and a pipeline.
#pragma once

#include <tbb/task_arena.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/process/process.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/run_config.hpp"
#include "daemon/thread_priority.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::daemon {

// One lane: which recorded pairs it is offered (every pair, or every Nth), its bounded queue
// (LiveMailbox: at most `capacity` waiting, the oldest dropped when full, every drop counted), its
// pipeline (run_live_pipeline) and its counters. The pipeline runs in a tbb::task_arena of the
// lane's priority: oneTBB gives its worker threads to the work of higher-priority arenas first, so
// the quality lane's reconstruction runs on the cores the live lane leaves idle. Every thread that
// works in the arena runs at the lane's niceness, below the recording's (thread_priority.hpp), and
// the lane's own thread at Options::caller_nice.
class Lane {
 public:
  struct Options {
    std::string name;  // "live" or "quality": status, logs
    process::Tier tier = process::Tier::full;
    std::string policy = "newest";  // "newest" or "every N", as status says it
    TakeOrder order = TakeOrder::newest;
    std::uint64_t every = 1;  // pairs whose index is a multiple of it are offered; 1: all
    std::size_t capacity = 2;
    int max_in_flight = 1;
    tbb::task_arena::priority priority = tbb::task_arena::priority::normal;
    int nice = 0;  // the niceness of the lane's threads, 0-19; 0: the caller's
    // The niceness of the thread that runs the lane (its pipeline's own thread), 0-19; -1: `nice`.
    int caller_nice = -1;
    // Threads working in the arena at once, the lane's own thread included; 0: as many as cores.
    int max_concurrency = 0;
    // The gate this lane keeps closed while it has a pair in flight or waiting (the live lane's),
    // and the gate its pairs wait at between their steps (the quality lane's: the live lane's
    // gate); either may be none.
    std::shared_ptr<PriorityGate> holds;
    std::shared_ptr<const PriorityGate> yields_to;
  };
  explicit Lane(Options options);
  Lane(const Lane&) = delete;
  Lane& operator=(const Lane&) = delete;

  // Queues a recorded pair if the lane's policy takes it (never blocks).
  void offer(const SharedPair& pair);
  // No more pairs; with `clear` (a stop) the waiting ones are dropped (they are on disk).
  void close(bool clear);
  // Runs the lane's pipeline in its arena until its queue is closed and empty (run_live_pipeline's
  // contract: a pair whose processing throws is counted and skipped; once `cancel` is set the pairs
  // in flight give up). An exception from `output` ends the lane and is thrown here.
  void run(const ProcessFn& process, const OutputFn& output, const CancelFlag& cancel);
  // Takes and forgets every pair until the queue is closed (a daemon with no processing stage).
  void discard_all();

  const std::string& name() const { return options_.name; }
  process::Tier tier() const { return options_.tier; }
  const LiveMailbox& queue() const { return queue_; }
  const PipelineStats& stats() const { return stats_; }
  // Pairs offered that the lane made no field of: dropped from its queue, failed or cancelled.
  std::uint64_t skipped() const;
  msg::LaneCounters counters() const;

 private:
  // Tells options_.holds whether this lane has a pair in flight or waiting.
  void reassess_gate();

  Options options_;
  LiveMailbox queue_;
  std::atomic<int> pairs_in_process_{0};
  PipelineStats stats_;
  tbb::task_arena arena_;
  ArenaNiceness niceness_;
};

// The niceness of the quality lane's own thread: the lowest, so that the kernel, not only oneTBB's
// task boundaries, gives the live lane (and the recording) the cores whenever they have work.
inline constexpr int kQualityLaneNice = 19;

// The lanes of a run, the live lane first: it runs the live tier when the spec has one (else the
// full settings) on the newest pair, max_pairs_in_flight at once, live_queue waiting, at high
// priority; the quality lane (config.quality.on()) runs the full settings on the pairs its policy
// takes, QualityLane::kPairsInFlight at once, quality.queue waiting, at low priority, its own
// thread at kQualityLaneNice and its arena one thread short of the cores (a oneTBB worker always
// free for the live lane), and its pairs wait between their steps while the live lane has a pair
// in flight or waiting (PriorityGate): it works on the time the live lane leaves. The other threads of both
// lanes run at `nice` (plenopivd.yaml `processing_nice`).
std::vector<std::unique_ptr<Lane>> make_lanes(const RunConfig& config, int nice = 0);

}  // namespace plenopiv::daemon
