// What every trigger backend shares: plays a schedule on a thread, pairs Q-switch sync edges into
// measured shots, keeps counters, and drives all lines low on stop, error and destruction.
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>

#include "drivers/trigger/trigger.hpp"

namespace plenopiv::drivers {

// Pairs Q-switch sync edges (one input, both cavities) into shots: the first edge of a shot is
// pulse 1, the next within `max_dt_s` is pulse 2. An edge with no partner is counted. Pure.
class ShotPairer {
 public:
  explicit ShotPairer(double max_dt_s = 0.01) : max_dt_ns_(std::uint64_t(max_dt_s * 1e9)) {}
  std::optional<MeasuredShot> push(std::uint64_t edge_ns);
  // An edge waiting since before `now_ns - max_dt` will not get a partner.
  void expire(std::uint64_t now_ns);
  std::uint64_t unpaired() const { return unpaired_; }
  void set_max_dt(double max_dt_s) { max_dt_ns_ = std::uint64_t(max_dt_s * 1e9); }

 private:
  std::uint64_t max_dt_ns_;
  std::optional<std::uint64_t> first_;
  std::uint64_t shots_ = 0;
  std::uint64_t unpaired_ = 0;
};

class ScheduledTrigger : public Trigger {
 public:
  ~ScheduledTrigger() override;  // backends call stop_playback() in their own destructor first
  TriggerInfo info() const override { return info_; }
  void load(const Schedule& schedule) override;
  void start(std::uint64_t shots) override;
  void stop() override;
  bool running() const override { return running_; }
  std::optional<MeasuredShot> next_shot(std::chrono::milliseconds timeout) override;
  TriggerCounters counters() const override;

 protected:
  explicit ScheduledTrigger(TriggerInfo info) : info_(std::move(info)) {}
  // Sets one output line. May throw DeviceError; the playback then stops with all lines low.
  virtual void write_line(TriggerLine line, bool level) = 0;
  // Every output low. Must not throw.
  virtual void all_low() noexcept = 0;
  // Virtual time (tests): edges are written at once, stamped with their planned times.
  virtual bool virtual_time() const { return false; }
  // Time stamp of "now" on the clock edges are reported in (ns).
  virtual std::uint64_t now_ns() const;
  // A Q-switch sync edge was seen at `edge_ns` (backend thread).
  void report_sync_edge(std::uint64_t edge_ns);
  // Called by the playback thread just after an edge was written (sim records it): the edge, its
  // shot, when it was planned (s from the start of playback) and how late it was written (s).
  virtual void on_edge_written(const Edge&, std::uint64_t, double, double) {}
  // Virtual time only: how late (ns, >= 0) the playback writes edge `edge_index` of shot `shot`,
  // standing in for a thread that runs late. Edges are never written before the one before them.
  virtual std::int64_t virtual_delay_ns(std::uint64_t /*shot*/, std::size_t /*edge_index*/) const { return 0; }
  // Names the physical output behind `line` (the laser cavity it fires), the key under which this
  // process remembers when that line last rose: the default is the URI and the line's name.
  virtual std::string line_identity(TriggerLine line) const;
  // Stops and joins the playback thread; backends call it first thing in their destructor,
  // while their write_line/all_low still work.
  void stop_playback() noexcept;
  std::string last_error() const;

 private:
  void play(Schedule schedule, std::uint64_t shots);

  TriggerInfo info_;
  std::optional<Schedule> schedule_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> stop_requested_{false};
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  TriggerCounters counters_;
  ShotPairer sync_pairer_;
  std::deque<MeasuredShot> shots_;
  std::string last_error_;
};

}  // namespace plenopiv::drivers
