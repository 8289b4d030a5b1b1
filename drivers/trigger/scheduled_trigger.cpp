// What every trigger backend shares: plays a schedule on a thread, pairs Q-switch sync edges into
// measured shots, keeps counters, and drives all lines low on stop, error and destruction.
#include "drivers/trigger/scheduled_trigger.hpp"

#include <algorithm>
#include <ctime>

#include "core/base/errors.hpp"
#include "drivers/common/driver_errors.hpp"

namespace plenopiv::drivers {

std::optional<MeasuredShot> ShotPairer::push(std::uint64_t edge_ns) {
  if (first_ && edge_ns >= *first_ && edge_ns - *first_ <= max_dt_ns_) {
    MeasuredShot shot{shots_++, *first_, edge_ns};
    first_.reset();
    return shot;
  }
  if (first_) ++unpaired_;
  first_ = edge_ns;
  return std::nullopt;
}

void ShotPairer::expire(std::uint64_t now_ns) {
  if (first_ && now_ns > *first_ + max_dt_ns_) {
    ++unpaired_;
    first_.reset();
  }
}

ScheduledTrigger::~ScheduledTrigger() { stop_playback(); }

std::uint64_t ScheduledTrigger::now_ns() const {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::uint64_t(ts.tv_sec) * 1'000'000'000ull + std::uint64_t(ts.tv_nsec);
}

void ScheduledTrigger::load(const Schedule& schedule) {
  if (running_) throw StateError("trigger " + info_.uri + ": load is not allowed while running");
  for (const Edge& e : schedule.edges) {
    if (std::find(info_.outputs.begin(), info_.outputs.end(), e.line) == info_.outputs.end()) {
      throw InputError("trigger " + info_.uri + ": the schedule drives line '" +
                       to_string(e.line) + "' but it is not wired (add " + to_string(e.line) +
                       "=<line> to the URI)");
    }
  }
  if (info_.timing_uncertainty_s > 0 && schedule.smallest_margin_s < info_.timing_uncertainty_s) {
    throw InputError("trigger " + info_.uri + ": " + info_.backend + " places edges to within +-" +
                     std::to_string(info_.timing_uncertainty_s * 1e6) +
                     " us, more than the schedule's smallest margin (" +
                     schedule.smallest_margin_what + ": " +
                     std::to_string(schedule.smallest_margin_s * 1e6) +
                     " us). Use hardware-timed mode (make_gate_schedule): an external delay "
                     "generator makes the pulses, plenopiv only arms it and gates the shot train");
  }
  std::lock_guard lock(mutex_);
  // Pulse 2 follows pulse 1 by dt; anything within half a period belongs to the same shot.
  sync_pairer_.set_max_dt(std::max(schedule.dt_s() * 1.5, schedule.period_s / 2));
  schedule_ = schedule;
}

void ScheduledTrigger::start(std::uint64_t shots) {
  if (running_) throw StateError("trigger " + info_.uri + ": already running");
  if (!schedule_) throw StateError("trigger " + info_.uri + ": start before load");
  if (thread_.joinable()) thread_.join();
  stop_requested_ = false;
  running_ = true;
  thread_ = std::thread([this, s = *schedule_, shots] { play(s, shots); });
}

void ScheduledTrigger::stop() {
  stop_playback();
  all_low();
}

void ScheduledTrigger::stop_playback() noexcept {
  stop_requested_ = true;
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  running_ = false;
}

void ScheduledTrigger::play(Schedule schedule, std::uint64_t shots) {
  using clock = std::chrono::steady_clock;
  // A little lead so the first edges are not late just because the thread was starting.
  const auto start = clock::now() + std::chrono::milliseconds(5);
  try {
    for (std::uint64_t k = 0; (shots == 0 || k < shots) && !stop_requested_; ++k) {
      for (const Edge& e : schedule.edges) {
        const double planned = double(k) * schedule.period_s + e.time_s;
        double lateness = 0;
        if (!virtual_time()) {
          const auto target = start + std::chrono::duration_cast<clock::duration>(
                                          std::chrono::duration<double>(planned));
          {
            std::unique_lock lock(mutex_);
            if (cv_.wait_until(lock, target, [this] { return stop_requested_.load(); })) break;
          }
          lateness = std::chrono::duration<double>(clock::now() - target).count();
        }
        write_line(e.line, e.rising);
        on_edge_written(e, k, planned, lateness);
        std::lock_guard lock(mutex_);
        ++counters_.edges_written;
        if (lateness > info_.timing_uncertainty_s && !virtual_time()) ++counters_.edges_late;
        counters_.worst_lateness_s = std::max(counters_.worst_lateness_s, lateness);
      }
      if (stop_requested_) break;
      std::lock_guard lock(mutex_);
      ++counters_.shots_fired;
    }
  } catch (const std::exception& e) {
    std::lock_guard lock(mutex_);
    last_error_ = e.what();
  }
  all_low();
  running_ = false;
  cv_.notify_all();
}

void ScheduledTrigger::report_sync_edge(std::uint64_t edge_ns) {
  std::lock_guard lock(mutex_);
  ++counters_.sync_edges;
  if (auto shot = sync_pairer_.push(edge_ns)) {
    shots_.push_back(*shot);
    if (shots_.size() > 1024) shots_.pop_front();  // nobody reads them: keep the newest
  }
  counters_.sync_unpaired = sync_pairer_.unpaired();
  cv_.notify_all();
}

std::optional<MeasuredShot> ScheduledTrigger::next_shot(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  if (!info_.measures_qswitch) return std::nullopt;
  cv_.wait_for(lock, timeout, [this] { return !shots_.empty(); });
  if (shots_.empty()) return std::nullopt;
  MeasuredShot s = shots_.front();
  shots_.pop_front();
  return s;
}

TriggerCounters ScheduledTrigger::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

std::string ScheduledTrigger::last_error() const {
  std::lock_guard lock(mutex_);
  return last_error_;
}

}  // namespace plenopiv::drivers
