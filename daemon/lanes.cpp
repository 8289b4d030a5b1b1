// A run's processing lanes: the live lane (every pair it can, fast tier, first call on the cores)
// and the quality lane (the full settings behind it), each a bounded queue and a pipeline.
#include "daemon/lanes.hpp"

#include <tbb/info.h>

#include <algorithm>

namespace plenopiv::daemon {

Lane::Lane(Options options)
    : options_(std::move(options)),
      queue_(options_.capacity, options_.order),
      arena_(options_.max_concurrency > 0 ? options_.max_concurrency : int(tbb::task_arena::automatic), 1,
             options_.priority),
      niceness_(arena_, options_.nice, options_.caller_nice) {}

void Lane::offer(const SharedPair& pair) {
  if (options_.every > 1 && pair->pair_index % options_.every != 0) return;
  queue_.push(pair);
  reassess_gate();
}

void Lane::reassess_gate() {
  if (options_.holds) options_.holds->reassess([this] { return pairs_in_process_ > 0 || queue_.depth() > 0; });
}

void Lane::close(bool clear) {
  if (clear) {
    queue_.close_and_clear();
  } else {
    queue_.close();
  }
  reassess_gate();
}

void Lane::run(const ProcessFn& process, const OutputFn& output, const CancelFlag& cancel) {
  ProcessFn holding = process;
  if (options_.holds) {
    holding = [this, &process](const drivers::FramePair& pair, const PairSteps& steps) {
      ++pairs_in_process_;
      reassess_gate();
      struct Done {
        Lane& lane;
        ~Done() {
          --lane.pairs_in_process_;
          lane.reassess_gate();
        }
      } done{*this};
      return process(pair, steps);
    };
  }
  arena_.execute([&] {
    run_live_pipeline(queue_, options_.max_in_flight, holding, output, stats_, cancel, options_.yields_to.get());
  });
}

void Lane::discard_all() {
  while (queue_.take()) {
    // Never taken by a pipeline: counted as dropped, as if a newer pair had taken its place.
  }
}

std::uint64_t Lane::skipped() const { return queue_.dropped() + stats_.process.skipped + stats_.process.cancelled; }

msg::LaneCounters Lane::counters() const {
  msg::LaneCounters m;
  m.set_name(options_.name);
  m.set_tier(process::tier_name(options_.tier));
  m.set_policy(options_.policy);
  m.set_queue_capacity(std::uint32_t(queue_.capacity()));
  m.set_queue_depth(std::uint32_t(queue_.depth()));
  m.set_offered(queue_.pushed());
  m.set_processed(stats_.output.processed);
  m.set_dropped(queue_.dropped());
  m.set_failed(stats_.process.skipped);
  m.set_cancelled(stats_.process.cancelled);
  m.set_in_flight(stats_.process.in_flight);
  const std::uint64_t n = stats_.process.processed;
  m.set_mean_time_s(n ? double(stats_.process.busy_ns) * 1e-9 / double(n) : 0.0);
  m.set_waited_s(double(stats_.process.waited_ns) * 1e-9);
  m.set_activity(stats_.activity.text());
  return m;
}

std::vector<std::unique_ptr<Lane>> make_lanes(const RunConfig& config, int nice) {
  std::vector<std::unique_ptr<Lane>> lanes;
  Lane::Options live;
  live.name = "live";
  live.tier = config.live_lane_tier();
  live.capacity = std::size_t(config.live_queue);
  live.max_in_flight = config.max_pairs_in_flight;
  live.priority = tbb::task_arena::priority::high;
  live.nice = nice;
  // Closed while the live lane has a pair in flight or waiting; the quality lane's pairs wait at it.
  const auto gate = config.quality.on() ? std::make_shared<PriorityGate>() : nullptr;
  live.holds = gate;
  lanes.push_back(std::make_unique<Lane>(live));
  if (config.quality.on()) {
    Lane::Options quality;
    quality.name = "quality";
    quality.tier = process::Tier::full;
    quality.policy = config.quality.policy();
    const bool every = config.quality.take == QualityLane::Take::every;
    quality.order = every ? TakeOrder::oldest : TakeOrder::newest;
    quality.every = every ? config.quality.every : 1;
    quality.capacity = std::size_t(config.quality.queue);
    quality.max_in_flight = QualityLane::kPairsInFlight;
    quality.priority = tbb::task_arena::priority::low;
    quality.nice = nice;
    quality.caller_nice = kQualityLaneNice;
    quality.max_concurrency = std::max(1, tbb::info::default_concurrency() - 1);
    quality.yields_to = gate;
    lanes.push_back(std::make_unique<Lane>(quality));
  }
  return lanes;
}

}  // namespace plenopiv::daemon
