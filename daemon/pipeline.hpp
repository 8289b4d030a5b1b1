// The live path: a bounded tbb::parallel_pipeline from recorded pairs to published vector fields.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>

#include "core/base/grid.hpp"
#include "drivers/camera/camera.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::daemon {

using SharedPair = std::shared_ptr<const drivers::FramePair>;

// What the processing stage makes of a pair.
struct ProcessedPair {
  VectorField vectors;
  std::optional<Volume> volume_a, volume_b;  // when the run publishes volumes
};

// The processing stage: preprocess, reconstruct A and B, correlate. Called concurrently for
// different pairs; it must not keep state between calls except read-only setup.
using ProcessFn = std::function<ProcessedPair(const drivers::FramePair&)>;

// Pairs recorded and waiting for the live path. The acquisition side pushes every recorded pair;
// the pipeline takes only the newest and counts the ones it passed over as skipped (they are on
// disk already). Thread safe.
class LiveMailbox {
 public:
  void push(SharedPair pair);
  void close();  // no more pairs: take() returns nullopt once empty
  // Blocks until a pair or close. Returns the newest pair; `skipped` gets the older ones' count.
  std::optional<SharedPair> take(std::uint64_t& skipped);
  std::size_t depth() const;

 private:
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<SharedPair> pairs_;
  bool closed_ = false;
};

// Per-stage counters, updated by the stages, read by status at any time.
struct StageStats {
  std::atomic<std::uint64_t> processed{0};
  std::atomic<std::uint64_t> skipped{0};
  std::atomic<std::uint64_t> busy_ns{0};
  std::atomic<std::uint32_t> in_flight{0};
  void add_time(std::chrono::steady_clock::duration d) {
    busy_ns += std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(d).count());
  }
  msg::StageCounters to_message(const char* name, std::uint32_t queue_depth) const;
};

struct PipelineStats {
  StageStats input, process, output;
};

// Output of the last (serial, in order) stage: publish and accumulate statistics.
using OutputFn = std::function<void(const drivers::FramePair&, ProcessedPair&)>;

// Runs until the mailbox is closed and empty. At most `max_in_flight` pairs are between input
// and output at once; output sees pairs in increasing pair order. A pair whose processing throws
// is counted as skipped on the processing stage and not output; the run goes on.
void run_live_pipeline(LiveMailbox& mailbox, int max_in_flight, const ProcessFn& process,
                       const OutputFn& output, PipelineStats& stats);

}  // namespace plenopiv::daemon
