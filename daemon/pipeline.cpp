// The live path: a bounded tbb::parallel_pipeline from recorded pairs to published vector fields.
#include "daemon/pipeline.hpp"

#include <spdlog/spdlog.h>
#include <tbb/parallel_pipeline.h>

#include "core/base/errors.hpp"

namespace plenopiv::daemon {

using Clock = std::chrono::steady_clock;

void LiveMailbox::push(SharedPair pair) {
  {
    std::lock_guard lock(mutex_);
    ++pushed_;
    pairs_.push_back(std::move(pair));
    while (pairs_.size() > capacity_) {
      pairs_.pop_front();
      ++dropped_;
    }
  }
  ready_.notify_one();
}

void LiveMailbox::close() {
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
  }
  ready_.notify_all();
}

void LiveMailbox::close_and_clear() {
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    dropped_ += pairs_.size();
    pairs_.clear();
  }
  ready_.notify_all();
}

std::optional<SharedPair> LiveMailbox::take() {
  std::unique_lock lock(mutex_);
  ready_.wait(lock, [&] { return closed_ || !pairs_.empty(); });
  if (pairs_.empty()) return std::nullopt;
  if (order_ == TakeOrder::oldest) {
    SharedPair oldest = std::move(pairs_.front());
    pairs_.pop_front();
    return oldest;
  }
  dropped_ += pairs_.size() - 1;
  SharedPair newest = std::move(pairs_.back());
  pairs_.clear();
  return newest;
}

bool LiveMailbox::wait_closed_for(std::chrono::steady_clock::duration timeout) {
  std::unique_lock lock(mutex_);
  return ready_.wait_for(lock, timeout, [&] { return closed_; });
}

std::uint64_t LiveMailbox::pushed() const {
  std::lock_guard lock(mutex_);
  return pushed_;
}

std::size_t LiveMailbox::depth() const {
  std::lock_guard lock(mutex_);
  return pairs_.size();
}

std::uint64_t LiveMailbox::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

msg::StageCounters StageStats::to_message(const char* name, std::uint32_t queue_depth, std::uint64_t dropped) const {
  msg::StageCounters m;
  m.set_name(name);
  m.set_processed(processed);
  m.set_skipped(skipped + cancelled);
  m.set_dropped(dropped);
  m.set_queue_depth(queue_depth);
  const std::uint64_t n = processed;
  m.set_mean_time_s(n ? double(busy_ns) * 1e-9 / double(n) : 0.0);
  return m;
}

namespace {
struct Item {
  SharedPair pair;
  std::optional<ProcessedPair> result;  // empty when processing failed
};
}  // namespace

void run_live_pipeline(LiveMailbox& mailbox, int max_in_flight, const ProcessFn& process, const OutputFn& output,
                       PipelineStats& stats, const CancelFlag& cancel) {
  tbb::parallel_pipeline(
      std::size_t(max_in_flight),
      tbb::make_filter<void, std::shared_ptr<Item>>(tbb::filter_mode::serial_in_order,
                                                    [&](tbb::flow_control& fc) -> std::shared_ptr<Item> {
                                                      std::optional<SharedPair> pair = mailbox.take();
                                                      if (!pair) {
                                                        fc.stop();
                                                        return nullptr;
                                                      }
                                                      ++stats.input.processed;
                                                      ++stats.process.in_flight;
                                                      auto item = std::make_shared<Item>();
                                                      item->pair = std::move(*pair);
                                                      return item;
                                                    }) &
          tbb::make_filter<std::shared_ptr<Item>, std::shared_ptr<Item>>(
              tbb::filter_mode::parallel,
              [&](std::shared_ptr<Item> item) {
                const auto start = Clock::now();
                try {
                  if (cancel) throw Cancelled("run stopping");
                  item->result = process(*item->pair, cancel);
                  ++stats.process.processed;
                } catch (const Cancelled&) {
                  ++stats.process.cancelled;
                } catch (const std::exception& e) {
                  ++stats.process.skipped;
                  spdlog::warn("pair {}: processing failed: {}", item->pair->pair_index, e.what());
                }
                stats.process.add_time(Clock::now() - start);
                --stats.process.in_flight;
                return item;
              }) &
          tbb::make_filter<std::shared_ptr<Item>, void>(tbb::filter_mode::serial_in_order,
                                                        [&](std::shared_ptr<Item> item) {
                                                          if (!item->result) return;
                                                          const auto start = Clock::now();
                                                          output(*item->pair, *item->result);
                                                          ++stats.output.processed;
                                                          stats.output.add_time(Clock::now() - start);
                                                        }));
}

}  // namespace plenopiv::daemon
