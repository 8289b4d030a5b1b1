// The live path: a bounded tbb::parallel_pipeline from recorded pairs to published vector fields.
#include "daemon/pipeline.hpp"

#include <spdlog/spdlog.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task.h>

#include <utility>

#include "core/base/errors.hpp"

namespace plenopiv::daemon {

using Clock = std::chrono::steady_clock;

void PriorityGate::reassess(const std::function<bool()>& busy_now) {
  bool freed = false;
  {
    std::lock_guard lock(mutex_);
    const bool busy = busy_now();
    freed = busy_ && !busy;
    busy_ = busy;
  }
  if (freed) free_.notify_all();
}

Clock::duration PriorityGate::wait_turn(const CancelFlag& cancel) const {
  const auto start = Clock::now();
  std::unique_lock lock(mutex_);
  // `cancel` is set without this lock: looked at every 50 ms, so that a stop is not held up.
  while (busy_ && !cancel) free_.wait_for(lock, std::chrono::milliseconds(50));
  return Clock::now() - start;
}

std::string measured_so_far(double fraction, double elapsed_s) {
  const auto duration = [](double s) {
    return s < 90 ? fmt::format("{:.0f} s", s) : fmt::format("{:.0f} min", s / 60);
  };
  std::string text = fmt::format("{:.0f} % measured, {} so far", 100 * fraction, duration(elapsed_s));
  if (fraction > 0 && fraction < 1) text += ", about " + duration(elapsed_s * (1 - fraction) / fraction) + " left";
  return text;
}

void StageActivity::set(std::string text) {
  const std::lock_guard lock(mutex_);
  text_ = std::move(text);
}

std::string StageActivity::text() const {
  const std::lock_guard lock(mutex_);
  return text_;
}

void PairSteps::step() const {
  if (yield_to_) waited_ += yield_to_->wait_turn(cancel_);
  if (cancel_) throw Cancelled("run stopping");
}

std::function<void()> LiveMailbox::due_waiter_locked() {
  if (!closed_ && pairs_.empty()) return {};
  return std::exchange(waiter_, {});
}

void LiveMailbox::push(SharedPair pair) {
  std::function<void()> wake;
  {
    std::lock_guard lock(mutex_);
    ++pushed_;
    pairs_.push_back(std::move(pair));
    while (pairs_.size() > capacity_) {
      pairs_.pop_front();
      ++dropped_;
    }
    wake = due_waiter_locked();
  }
  ready_.notify_one();
  if (wake) wake();
}

void LiveMailbox::close() {
  std::function<void()> wake;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    wake = due_waiter_locked();
  }
  ready_.notify_all();
  if (wake) wake();
}

void LiveMailbox::close_and_clear() {
  std::function<void()> wake;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    dropped_ += pairs_.size();
    pairs_.clear();
    wake = due_waiter_locked();
  }
  ready_.notify_all();
  if (wake) wake();
}

void LiveMailbox::call_when_ready(std::function<void()> wake) {
  {
    std::lock_guard lock(mutex_);
    if (!closed_ && pairs_.empty()) {
      waiter_ = std::move(wake);
      return;
    }
  }
  wake();
}

std::optional<SharedPair> LiveMailbox::take() {
  std::unique_lock lock(mutex_);
  ready_.wait(lock, [&] { return closed_ || !pairs_.empty(); });
  return take_locked();
}

std::optional<SharedPair> LiveMailbox::try_take(bool& closed) {
  std::lock_guard lock(mutex_);
  closed = closed_ && pairs_.empty();
  return take_locked();
}

std::optional<SharedPair> LiveMailbox::take_locked() {
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

// The mailbox's next pair, nullopt once it is closed and empty. While it is empty the calling task
// is suspended, and its thread goes on with the arena's other work until a push or close resumes
// the task (on a thread of the arena).
std::optional<SharedPair> next_pair(LiveMailbox& mailbox) {
  for (;;) {
    bool closed = false;
    if (std::optional<SharedPair> pair = mailbox.try_take(closed)) return pair;
    if (closed) return std::nullopt;
    tbb::task::suspend(
        [&](tbb::task::suspend_point tag) { mailbox.call_when_ready([tag] { tbb::task::resume(tag); }); });
  }
}
}  // namespace

void run_live_pipeline(LiveMailbox& mailbox, int max_in_flight, const ProcessFn& process, const OutputFn& output,
                       PipelineStats& stats, const CancelFlag& cancel, const PriorityGate* yield_to) {
  tbb::parallel_pipeline(
      std::size_t(max_in_flight),
      tbb::make_filter<void, std::shared_ptr<Item>>(tbb::filter_mode::serial_in_order,
                                                    [&](tbb::flow_control& fc) -> std::shared_ptr<Item> {
                                                      std::optional<SharedPair> pair = next_pair(mailbox);
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
                const PairSteps steps(cancel, yield_to, &stats.activity);
                try {
                  steps.step();
                  item->result = process(*item->pair, steps);
                  ++stats.process.processed;
                } catch (const Cancelled&) {
                  ++stats.process.cancelled;
                } catch (const std::exception& e) {
                  ++stats.process.skipped;
                  spdlog::warn("pair {}: processing failed: {}", item->pair->pair_index, e.what());
                }
                stats.process.add_time(Clock::now() - start - steps.waited());
                stats.process.add_wait(steps.waited());
                steps.say({});
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
