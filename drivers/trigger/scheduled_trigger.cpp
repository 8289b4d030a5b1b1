// What every trigger backend shares: plays a schedule on a thread, pairs Q-switch sync edges into
// measured shots, keeps counters, and drives all lines low on stop, error and destruction.
#include "drivers/trigger/scheduled_trigger.hpp"

#include <algorithm>
#include <array>
#include <ctime>
#include <limits>
#include <map>

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
  check_schedule(schedule);
  for (const Edge& e : schedule.edges) {
    if (std::find(info_.outputs.begin(), info_.outputs.end(), e.line) == info_.outputs.end()) {
      throw InputError("trigger " + info_.uri + ": the schedule drives line '" + to_string(e.line) +
                       "' but it is not wired (add " + to_string(e.line) + "=<line> to the URI)");
    }
  }
  if (info_.timing_uncertainty_s > 0 && schedule.smallest_margin_s < info_.timing_uncertainty_s) {
    throw InputError("trigger " + info_.uri + ": " + info_.backend + " places edges to within +-" +
                     std::to_string(info_.timing_uncertainty_s * 1e6) +
                     " us, more than the schedule's smallest margin (" + schedule.smallest_margin_what + ": " +
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

namespace {

// When each laser line last rose in this process (steady clock, ns since its epoch), keyed by the
// line's identity: a run that starts right after another on the same laser waits out the laser's
// minimum interval too, although each run opens its own trigger.
class LaserHistory {
 public:
  static LaserHistory& instance() {
    static LaserHistory history;
    return history;
  }
  std::optional<std::int64_t> last(const std::string& line) const {
    std::lock_guard lock(mutex_);
    auto it = last_.find(line);
    if (it == last_.end()) return std::nullopt;
    return it->second;
  }
  void rose(const std::string& line, std::int64_t when_ns) {
    std::lock_guard lock(mutex_);
    last_[line] = when_ns;
  }

 private:
  mutable std::mutex mutex_;
  std::map<std::string, std::int64_t> last_;
};

std::int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

std::string ScheduledTrigger::line_identity(TriggerLine line) const { return info_.uri + "#" + to_string(line); }

void ScheduledTrigger::play(Schedule schedule, std::uint64_t shots) {
  using clock = std::chrono::steady_clock;
  const std::int64_t period = schedule.period_ns;
  const std::int64_t min_interval = schedule.min_laser_interval_ns;
  // A little lead so the first edges are not late just because the thread was starting; later
  // still when a laser line fired in this process (a run just before this one) too recently for
  // the first shot.
  std::int64_t start_ns = steady_ns() + 5'000'000;
  std::array<std::optional<std::int64_t>, kTriggerLines.size()> history;
  if (!virtual_time()) {
    for (const Edge& e : schedule.edges) {
      if (!e.rising || !is_laser_line(e.line)) continue;
      if (auto t = LaserHistory::instance().last(line_identity(e.line))) {
        history[int(e.line)] = *t;
        start_ns = std::max(start_ns, *t + min_interval - e.time_ns);
      }
    }
  }
  const auto start = clock::time_point(std::chrono::nanoseconds(start_ns));
  // Times below are ns from `start` (virtual time: from the first planned edge). The last rising
  // edge of each laser line, starting from what this process last fired on it.
  std::array<std::optional<std::int64_t>, kTriggerLines.size()> last_rise;
  for (TriggerLine l : kTriggerLines) {
    if (history[int(l)]) last_rise[int(l)] = *history[int(l)] - start_ns;
  }
  std::array<bool, kTriggerLines.size()> high{};
  std::int64_t last_written = std::numeric_limits<std::int64_t>::min();
  // Lowers every line that is high, as edges written at `now` (a shot given up half way).
  const auto lower_all = [&](std::uint64_t k, std::int64_t now) {
    for (TriggerLine l : kTriggerLines) {
      if (!high[int(l)]) continue;
      write_line(l, false);
      high[int(l)] = false;
      const Edge down{now - std::int64_t(k) * period, double(now - std::int64_t(k) * period) * 1e-9, l, false};
      // (time relative to the shot's planned start; only the sim trigger records it)
      on_edge_written(down, k, double(now) * 1e-9, 0.0);
    }
  };
  try {
    for (std::uint64_t k = 0; (shots == 0 || k < shots) && !stop_requested_; ++k) {
      // k * period + an edge's time stays within 64 bits (k beyond ~2.5e6 shots of the longest period).
      if (k >= std::uint64_t(std::numeric_limits<std::int64_t>::max() / period) - 1) break;
      // A shot that would fire a laser line sooner after that line's last rising edge than the laser
      // allows (the playback wrote the previous shot late) is played later, whole, so that its own
      // timing (flashlamp to Q-switch, dt, camera) holds too.
      std::int64_t shot_start = std::int64_t(k) * period;
      std::int64_t shift = 0;
      for (const Edge& e : schedule.edges) {
        if (!e.rising || !is_laser_line(e.line) || !last_rise[int(e.line)]) continue;
        shift = std::max(shift, *last_rise[int(e.line)] + min_interval - (shot_start + e.time_ns));
      }
      if (shift > 0) {
        shot_start += shift;
        std::lock_guard lock(mutex_);
        ++counters_.shots_delayed;
      }
      bool stopped = false;
      for (std::size_t i = 0; i < schedule.edges.size(); ++i) {
        const Edge& e = schedule.edges[i];
        const std::int64_t planned = shot_start + e.time_ns;
        std::int64_t now = planned;
        if (virtual_time()) {
          now = std::max(planned + std::max<std::int64_t>(0, virtual_delay_ns(k, i)), last_written);
        } else {
          const auto target = start + std::chrono::nanoseconds(planned);
          std::unique_lock lock(mutex_);
          if (cv_.wait_until(lock, target, [this] { return stop_requested_.load(); })) {
            stopped = true;
            break;
          }
          lock.unlock();
          now = std::max(steady_ns() - start_ns, planned);
        }
        // A laser line never rises sooner after its previous rising edge than the laser allows: the
        // shot was moved so that it does not, and should that ever fail, the rest of the shot is
        // given up and counted rather than fired.
        if (e.rising && is_laser_line(e.line) && last_rise[int(e.line)] &&
            now - *last_rise[int(e.line)] < min_interval) {
          lower_all(k, now);
          last_written = now;
          std::lock_guard lock(mutex_);
          ++counters_.shots_abandoned;
          break;
        }
        write_line(e.line, e.rising);
        high[int(e.line)] = e.rising;
        last_written = now;
        if (e.rising && is_laser_line(e.line)) {
          last_rise[int(e.line)] = now;
          if (!virtual_time()) LaserHistory::instance().rose(line_identity(e.line), start_ns + now);
        }
        const double lateness = double(now - planned) * 1e-9;
        on_edge_written(e, k, double(planned) * 1e-9, lateness);
        std::lock_guard lock(mutex_);
        ++counters_.edges_written;
        if (lateness > info_.timing_uncertainty_s && !virtual_time()) ++counters_.edges_late;
        counters_.worst_lateness_s = std::max(counters_.worst_lateness_s, lateness);
        if (i + 1 == schedule.edges.size()) ++counters_.shots_fired;
      }
      if (stopped || stop_requested_) break;
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
