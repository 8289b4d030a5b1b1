// One run: trigger → camera → recorder (every pair) → live pipeline → publisher, on its own threads.
#include "daemon/run.hpp"

#include <spdlog/spdlog.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <exception>
#include <limits>
#include <tuple>

#include "core/base/errors.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/direct_writer.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/frame_check.hpp"
#include "daemon/thread_priority.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/camera/frame_pool.hpp"
#include "drivers/common/driver_errors.hpp"
#include "drivers/trigger/camera_wiring.hpp"
#include "drivers/trigger/trigger_registry.hpp"

namespace plenopiv::daemon {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

namespace {

// Time between the two frames of a pair: B - A on the device clock when both frames carry it,
// else on the host clock. (Not the laser's dt: frame B starts after the interline transfer.)
double frame_gap_s(const drivers::FramePair& pair) {
  if (pair.a.device_timestamp_ns != 0 && pair.b.device_timestamp_ns != 0) {
    return (double(pair.b.device_timestamp_ns) - double(pair.a.device_timestamp_ns)) * 1e-9;
  }
  return (double(pair.b.host_timestamp_ns) - double(pair.a.host_timestamp_ns)) * 1e-9;
}

// Space kept free on the data directory's file system beyond the pairs themselves (manifest
// rewrites, vector fields, statistics, the rest of the system).
constexpr std::uint64_t kReserveBytes = 64ull * 1024 * 1024;
// A run without a pair count or duration needs room for at least this many pairs to start.
constexpr std::uint64_t kMinPairsUnbounded = 10;
// Runs that record at least this many bytes per second have the data directory's write rate
// measured before they start (the paper's camera from about 1.6 Hz; the small camera never), with a
// write of this size (a fraction of a second on a disk fast enough for them).
constexpr double kProbeWriteRateAbove = 100e6;
constexpr std::uint64_t kWriteProbeBytes = std::uint64_t(256) << 20;

std::string megabytes(std::uint64_t bytes) {
  char text[64];
  std::snprintf(text, sizeof text, "%.1f MB", double(bytes) / 1e6);
  return text;
}

std::string seconds(double s) {
  char text[64];
  std::snprintf(text, sizeof text, "%g s", s);
  return text;
}

}  // namespace

Run::Run(RunConfig config, std::string run_id, RunEnvironment env)
    : config_(std::move(config)), run_id_(std::move(run_id)), env_(std::move(env)) {
  const std::string camera_uri = config_.camera_uri.empty() ? env_.default_camera_uri : config_.camera_uri;
  const std::string trigger_uri = config_.trigger_uri.empty() ? env_.default_trigger_uri : config_.trigger_uri;
  if (camera_uri.empty()) {
    throw InputError("camera_uri: the run names no camera and plenopivd.yaml has no camera_uri");
  }
  lanes_ = make_lanes(config_, env_.processing_nice);
  if (config_.preview.on() && env_.publisher) {
    if (env_.camera_file.empty()) {
      throw InputError("preview: the alignment preview refocuses with the daemon's camera_file, and it has none");
    }
    preview_queue_ = std::make_unique<LiveMailbox>(1);
  }
  camera_ = drivers::open_camera(camera_uri);
  drivers::CameraSettings camera_settings;
  camera_settings.roi = config_.camera_roi;
  camera_->configure(camera_settings);
  trigger_ = drivers::open_trigger(trigger_uri);
  const drivers::TriggerInfo trigger_info = trigger_->info();
  trigger_->load(run_schedule(env_.timing, trigger_info, config_.rate_hz, config_.dt_s));
  const drivers::CameraWiring wiring = drivers::wire_camera(*trigger_, *camera_);
  camera_trigger_ = wiring.source;
  camera_->arm(drivers::DoubleExposureSettings{wiring.source, 0.0});
  const drivers::CameraInfo info = camera_->info();
  // Read once, checked against the camera file, and then the same bytes go to the processing and
  // into the run folder: a calibration file replaced later changes neither this run nor its copy.
  RunCalibration& calibration = calibration_;
  if (!env_.calibration_file.empty()) {
    if (env_.camera_file.empty()) {
      throw InputError("calibration_file: " + env_.calibration_file.string() +
                       ": needs camera_file (the camera it was made for)");
    }
    calibration = load_run_calibration(env_.calibration_file, optics::load_camera_file(env_.camera_file));
  }
  // The frames the camera delivers: its region, else its whole sensor.
  const drivers::Roi& roi = config_.camera_roi;
  const int frame_width = roi.width > 0 ? roi.width : info.sensor_width_px;
  const int frame_height = roi.height > 0 ? roi.height : info.sensor_height_px;
  // Frames of another size than the camera file's sensor would fail every pair of the plenoptic
  // processing, so such a run does not start.
  if (env_.processing && env_.processing_reads_camera_file && !env_.camera_file.empty()) {
    const optics::SensorSpec sensor = optics::load_camera_file(env_.camera_file).sensor();
    if (frame_width != sensor.width_px || frame_height != sensor.height_px) {
      const std::string frames = std::to_string(frame_width) + " x " + std::to_string(frame_height) + " px";
      throw InputError((roi.width > 0 ? "camera_roi: a region of " + frames
                                      : "camera_uri " + camera_uri + ": a sensor of " + frames) +
                       " does not match camera_file " + env_.camera_file.string() + ", whose sensor is " +
                       std::to_string(sensor.width_px) + " x " + std::to_string(sensor.height_px) +
                       " px: the processing could reconstruct no pair; give plenopivd the camera file of these "
                       "frames, or set camera_roi to the camera file's size");
    }
  }
  // The raw frames of the pairs this run plans must fit on the disk before it starts.
  bytes_per_pair_ =
      2 * std::uint64_t(std::max(frame_width, 0)) * std::uint64_t(std::max(frame_height, 0)) * sizeof(std::uint16_t);
  // Both saturate at the largest count rather than wrap or convert out of range: a run of 1e300 s
  // is refused for the disk it would need, not planned as a few pairs.
  constexpr std::uint64_t kMost = std::numeric_limits<std::uint64_t>::max();
  std::uint64_t planned = config_.pair_count;
  if (planned == 0 && config_.duration_s > 0) {
    const double pairs = std::ceil(config_.duration_s * config_.rate_hz);
    planned = pairs < 0x1p64 ? std::uint64_t(pairs) : kMost;
  }
  if (planned == 0) planned = kMinPairsUnbounded;
  std::filesystem::create_directories(env_.data_dir);
  bytes_planned_ = bytes_per_pair_ && planned > (kMost - kReserveBytes) / bytes_per_pair_
                       ? kMost
                       : planned * bytes_per_pair_ + kReserveBytes;
  if (const auto free = io::free_bytes(env_.data_dir)) {
    if (*free < bytes_planned_) {
      throw InputError("data_dir: " + env_.data_dir.string() + " has " + megabytes(*free) + " free; " +
                       std::to_string(planned) + " pairs of raw frames need " + megabytes(bytes_planned_) +
                       (config_.pair_count || config_.duration_s > 0 ? "" : " to start an unbounded run") +
                       ": free some space or record fewer pairs");
    }
  }
  run_folder::Writer::Setup& setup = setup_;
  setup.data_dir = env_.data_dir;
  setup.run_id = run_id_;
  setup.run_yaml = config_.text;
  setup.process_yaml = config_.process_yaml();
  setup.nominal_dt_s = config_.dt_s;
  setup.rate_hz = config_.rate_hz;
  setup.camera_uri = camera_uri;
  setup.trigger_uri = trigger_uri;
  setup.camera_file = env_.camera_file;
  setup.camera_model = info.vendor + " " + info.model + " " + info.serial;
  setup.camera_triggering = wiring.description;
  if (!calibration.nominal())
    setup.calibration = run_folder::CalibrationCopy{calibration.source, calibration.bytes, calibration.crc32};
  dir_ = run_folder::run_dir(env_.data_dir, run_id_);
  if (std::filesystem::exists(dir_)) throw InputError("run folder " + dir_.string() + ": exists already");
  spdlog::info("run {}: calibration {}", run_id_, calibration.summary());
  spdlog::info("run {}: {} pairs at {} Hz, dt {} s, from {}, trigger {}, folder {}", run_id_,
               config_.pair_count ? std::to_string(config_.pair_count) : "unlimited", config_.rate_hz, config_.dt_s,
               camera_uri, trigger_uri, dir_.string());
  spdlog::info("run {}: raw frames written {}", run_id_,
               io::direct_write_mode(env_.data_dir) == io::WriteMode::direct
                   ? "past the page cache (O_DIRECT)"
                   : "through the page cache: the data directory's file system does not take O_DIRECT in 4 KiB "
                     "blocks");
  if (wiring.source == drivers::TriggerSource::Software) {
    spdlog::warn("run {}: camera triggering {}", run_id_, wiring.description);
  } else {
    spdlog::info("run {}: camera triggering {}", run_id_, wiring.description);
  }
  thread_ = std::thread([this] { run(); });
}

Run::~Run() {
  request_stop();
  join();
}

void Run::join() {
  if (thread_.joinable()) thread_.join();
}

// Raw frames first: never dropped once delivered (unless the disk has no room for them).
void Run::record(drivers::FramePair pair) {
  // The run's trigger numbering (a reconnected camera counts from 0 again), which the shots share.
  pair.trigger_index += trigger_offset_;
  mark_accounted(pair.trigger_index);
  attach_shot(pair);
  check_space();
  run_folder::PairRecord record;
  record.pair_index = pair.pair_index;
  record.trigger_index = pair.trigger_index;
  record.frame_a = &pair.a.image;
  record.frame_b = &pair.b.image;
  record.frame_id_a = pair.a.frame_id;
  record.frame_id_b = pair.b.frame_id;
  record.device_timestamp_a_ns = pair.a.device_timestamp_ns;
  record.device_timestamp_b_ns = pair.b.device_timestamp_ns;
  record.host_timestamp_a_ns = pair.a.host_timestamp_ns;
  record.host_timestamp_b_ns = pair.b.host_timestamp_ns;
  record.frame_gap_s = frame_gap_s(pair);
  if (pair.measured) record.laser_pulses_ns = std::pair{pair.measured->pulse1_ns, pair.measured->pulse2_ns};
  // The frame check's statistics gathered as the frames are written, not by reading them again.
  process::FrameRange range_a, range_b;
  record.visit_rows_a = [&range_a](std::span<const std::uint16_t> rows) { range_a.add(rows); };
  record.visit_rows_b = [&range_b](std::span<const std::uint16_t> rows) { range_b.add(rows); };
  recorder_->record_pair(record);
  ++pairs_received_;
  check_frames(pair, range_a, range_b);
  if (env_.heartbeat) env_.heartbeat();
  // The frames go back to the camera's pool when the last consumer lets go of the pair.
  const SharedPair shared = drivers::share_pair(std::move(pair), camera_->frame_pool());
  for (const auto& lane : lanes_) lane->offer(shared);
  if (preview_queue_) preview_queue_->push(shared);
}

// A recorder slower than the camera falls behind and, its queue bounded, loses frames: where a run
// records fast enough for the disk to matter, the data directory's write rate is measured while
// Armed, on the run's thread (a burst: a disk that takes it may still slow down over minutes), and
// a rate below the run's is said before the first pair, not after the run as frames lost. A probe
// that fails is said too; the run goes on (its own checks of space stand).
void Run::check_write_rate() {
  const double needed = double(bytes_per_pair_) * config_.rate_hz;  // bytes per second
  if (needed < kProbeWriteRateAbove) return;
  // A new probe file must leave the run its room (one kept from an earlier run is overwritten).
  const auto free = io::free_bytes(env_.data_dir);
  if (free && *free < bytes_planned_ + kWriteProbeBytes &&
      !std::filesystem::exists(env_.data_dir / io::kWriteProbeName)) {
    spdlog::warn(
        "run {}: data_dir {}: no room for a {} MiB write probe beside this run's frames; whether the disk "
        "takes {:.0f} MB/s is not checked",
        run_id_, env_.data_dir.string(), kWriteProbeBytes >> 20, needed / 1e6);
    return;
  }
  double taken = 0;
  try {
    taken = io::measure_write_rate(env_.data_dir, kWriteProbeBytes);
  } catch (const std::exception& e) {
    spdlog::warn("run {}: could not time a write into data_dir {}: {}", run_id_, env_.data_dir.string(), e.what());
    return;
  }
  char rates[256];
  std::snprintf(rates, sizeof rates, "%.0f MB/s in a %llu MiB write; this run records %.0f MB/s (%s per pair at %g Hz)",
                taken / 1e6, static_cast<unsigned long long>(kWriteProbeBytes >> 20), needed / 1e6,
                megabytes(bytes_per_pair_).c_str(), config_.rate_hz);
  if (taken < needed) {
    const std::string warning = "data_dir " + env_.data_dir.string() + " took " + rates +
                                ": the recorder will fall behind and lose frames; lower rate_hz or record to a "
                                "faster disk";
    spdlog::warn("run {}: {}", run_id_, warning);
    std::lock_guard lock(warnings_mutex_);
    setup_warning_ = warning;
  } else {
    spdlog::info("run {}: data_dir {} took {}", run_id_, env_.data_dir.string(), rates);
  }
}

// A disk that is about to fill ends the run before a frame write fails half way.
void Run::check_space() const {
  const auto free = io::free_bytes(recorder_->dir());
  if (free && *free < bytes_per_pair_ + kReserveBytes / 4) {
    throw std::runtime_error("no space left on device for the next pair: " + megabytes(*free) + " free in " +
                             recorder_->dir().string() + ", a pair needs " + megabytes(bytes_per_pair_));
  }
}

// Frames that hold no information are recorded as they are, and flagged (process::frame_problem:
// all zero, or saturated), once per kind of problem in the log and manifest, counted in status.
void Run::check_frames(const drivers::FramePair& pair, const process::FrameRange& range_a,
                       const process::FrameRange& range_b) {
  for (const auto& [frame, range, name] : {std::tuple{&pair.a, &range_a, "A"}, std::tuple{&pair.b, &range_b, "B"}}) {
    const auto problem = process::frame_problem(frame->image.pixels, frame->bit_depth, *range);
    if (!problem) continue;
    const std::string kind = std::string("frame ") + name + " " + *problem;
    bool first = false;
    {
      std::lock_guard lock(warnings_mutex_);
      auto [it, fresh] = warnings_.try_emplace(kind, 0, pair.pair_index);
      ++it->second.first;
      first = fresh;
    }
    if (first) {
      spdlog::warn("run {}: pair {}: {}", run_id_, pair.pair_index, kind);
      recorder_->add_warning(kind + ", first in pair " + std::to_string(pair.pair_index));
    }
  }
}

void Run::take_drops() {
  const std::vector<drivers::PairDrop> drops = camera_->take_drops();
  if (drops.empty()) return;
  for (const drivers::PairDrop& d : drops) {
    const std::uint64_t index = d.trigger_index + trigger_offset_;
    mark_accounted(index);
    recorder_->record_drop(index, drivers::to_string(d.reason));
    spdlog::warn("run {}: trigger {}: no pair recorded: {}", run_id_, index, drivers::to_string(d.reason));
  }
}

// One software trigger, the run's `index`-th. While the camera is lost it is counted, not fired;
// a trigger the camera does not take (its control timed out) begins an outage.
void Run::fire_software_trigger(std::uint64_t index) {
  triggers_made_ = index + 1;
  if (outage_ && !camera_->status().connected) {
    lose_trigger(index);
    return;
  }
  try {
    camera_->software_trigger();
    if (outage_) end_outage(index);  // the camera took it: it is back
  } catch (const drivers::DeviceError& e) {
    if (outage_) {
      lose_trigger(index);
    } else {
      begin_outage(e.what(), index + 1);
    }
  }
}

// Follows the camera's connection: an outage begins when the driver reports the camera lost and
// ends when it has reconnected; one longer than the run's camera_outage_s fails the run.
void Run::watch_camera(Clock::time_point now) {
  const drivers::CameraStatus cs = camera_->status();
  if (cs.failed) throw drivers::DeviceError("camera " + camera_->info().uri + " failed: " + cs.last_error);
  if (camera_trigger_ != drivers::TriggerSource::Software) triggers_made_ = trigger_->counters().shots_fired;
  if (!cs.connected && !outage_) begin_outage(cs.last_error, triggers_made_);
  if (cs.connected && outage_ && camera_->counters().reconnects > outage_->reconnects) end_outage(triggers_made_);
  if (outage_ && now - outage_->since > std::chrono::duration<double>(config_.camera_outage_s)) {
    throw drivers::DeviceError("camera " + camera_->info().uri + " lost for more than " +
                               seconds(config_.camera_outage_s) + ": " +
                               (cs.last_error.empty() ? outage_->reason : cs.last_error));
  }
}

// The pairs the camera delivered before it was lost are recorded; the triggers up to `made` that
// it neither delivered nor dropped (their frames were still in the camera) are lost with it.
void Run::begin_outage(const std::string& reason, std::uint64_t made) {
  outage_ = Outage{Clock::now(), camera_->counters().reconnects, reason};
  spdlog::error("run {}: camera {} lost, waiting up to {} for it: {}", run_id_, camera_->info().uri,
                seconds(config_.camera_outage_s), reason);
  while (auto pair = camera_->next_pair(0ms)) record(std::move(*pair));
  take_drops();
  for (std::uint64_t i = triggers_seen(); i < made; ++i) lose_trigger(i);
}

// The camera is back, from the run's trigger `made` on; a camera that reconnected counts its
// triggers from 0 again there.
void Run::end_outage(std::uint64_t made) {
  for (std::uint64_t i = triggers_seen(); i < made; ++i) lose_trigger(i);
  if (camera_->counters().reconnects > outage_->reconnects) trigger_offset_ = made;
  spdlog::info("run {}: camera {} back after {:.1f} s; {} trigger(s) lost with it so far", run_id_, camera_->info().uri,
               std::chrono::duration<double>(Clock::now() - outage_->since).count(), camera_lost_.load());
  outage_.reset();
}

void Run::lose_trigger(std::uint64_t index) {
  mark_accounted(index);
  ++camera_lost_;
  recorder_->record_drop(index, "camera lost");
}

// The shot of a pair may still be on its way (a camera can deliver before the Q-switches fire):
// wait briefly for it; a pair whose shot never comes keeps measured_dt 0 ("not measured").
void Run::attach_shot(drivers::FramePair& pair) {
  if (!trigger_->info().measures_qswitch) return;
  const auto deadline = Clock::now() + 200ms;
  while (!joiner_.attach(pair)) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    if (left <= 0ms) return;
    const auto shot = trigger_->next_shot(left);
    if (!shot) return;
    joiner_.add_shot(*shot);
    if (shot->shot_index > pair.trigger_index) {
      joiner_.attach(pair);  // drops the older shots; this pair's is gone
      return;
    }
  }
}

void Run::stop_devices() noexcept {
  try {
    trigger_->stop();  // every line low
  } catch (const std::exception& e) {
    spdlog::error("run {}: stopping the trigger: {}", run_id_, e.what());
  }
  try {
    camera_->stop();  // bounded: what is not read out by then is dropped and counted
  } catch (const std::exception& e) {
    spdlog::error("run {}: stopping the camera: {}", run_id_, e.what());
  }
}

// Records the pairs the camera delivered before it stopped, for at most kStopRecordBound; any left
// after that are counted (and listed) as not recorded, so that a stop never waits without end.
void Run::drain_after_stop() {
  const auto deadline = Clock::now() + kStopRecordBound;
  while (auto pair = camera_->next_pair(0ms)) {
    if (Clock::now() < deadline) {
      record(std::move(*pair));
      continue;
    }
    ++not_recorded_at_stop_;
    const std::uint64_t index = pair->trigger_index + trigger_offset_;
    mark_accounted(index);
    recorder_->record_drop(index, "not recorded at the stop");
    spdlog::warn("run {}: trigger {}: not recorded: the stop's {} s bound was reached", run_id_, index,
                 kStopRecordBound.count() / 1000.0);
  }
  take_drops();
}

void Run::mark_accounted(std::uint64_t trigger_index) {
  if (trigger_index >= triggers_accounted_.size()) triggers_accounted_.resize(trigger_index + 1, false);
  triggers_accounted_[trigger_index] = true;
}

// The frames of the run's last triggers that never arrived leave no gap in the frame ids behind
// them for the camera's pairer to see: what the triggers made and no count holds is counted never
// arrived. A trigger whose frames all went missing (the pairer counts the frames, not the trigger)
// is neither recorded nor listed: it is listed now.
void Run::account_for_the_last_triggers() {
  if (camera_trigger_ != drivers::TriggerSource::Software) triggers_made_ = trigger_->counters().shots_fired;
  for (std::uint64_t i = 0; i < triggers_made_; ++i) {
    if (i < triggers_accounted_.size() && triggers_accounted_[i]) continue;
    recorder_->record_drop(i, "never arrived");
    spdlog::warn("run {}: trigger {}: no pair recorded: never arrived", run_id_, i);
  }
  const std::uint64_t accounted = 2 * recorder_->pairs_recorded() + frames_lost();
  if (2 * triggers_made_ > accounted) never_arrived_at_end_ = 2 * triggers_made_ - accounted;
}

void Run::acquire() {
  try {
    const auto period =
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / config_.rate_hz));
    const bool software = camera_trigger_ == drivers::TriggerSource::Software;
    trigger_->start(config_.pair_count);  // 0: until stopped
    const auto started = Clock::now();
    auto next_trigger = started;
    std::uint64_t fired = 0;
    std::optional<Clock::time_point> last_shot;  // when the trigger had played all its shots
    while (!stop_) {
      take_drops();
      watch_camera(Clock::now());
      const std::uint64_t received = pairs_received_;
      if (config_.pair_count && received >= config_.pair_count) break;
      const auto now = Clock::now();
      if (config_.duration_s > 0 && now - started >= std::chrono::duration<double>(config_.duration_s)) {
        break;
      }
      if (!trigger_->running() && !last_shot) {
        const drivers::TriggerCounters tc = trigger_->counters();
        // Shots given up by the laser guard are played too: they count towards the run's shots.
        const std::uint64_t shots = tc.shots_fired + tc.shots_abandoned;
        if (config_.pair_count == 0 || shots < config_.pair_count) {
          throw drivers::DeviceError("trigger " + trigger_->info().uri + " stopped by itself after " +
                                     std::to_string(shots) + " shots");
        }
        last_shot = now;
      }
      // A camera no line can reach: software triggers at rate_hz (the wiring said so, and the
      // manifest and log say it too).
      const bool more_to_fire = config_.pair_count == 0 || fired < config_.pair_count;
      if (software && more_to_fire && now >= next_trigger) {
        fire_software_trigger(fired);
        ++fired;
        next_trigger += period;
      }
      // All shots fired and the missing pairs never came (lost frames): end after a grace time.
      if (last_shot && (!software || !more_to_fire) && now - *last_shot > 2 * period + 1s) break;
      const auto wait =
          software ? std::clamp(std::chrono::duration_cast<std::chrono::milliseconds>(next_trigger - Clock::now()), 0ms,
                                50ms)
                   : 50ms;
      if (auto pair = camera_->next_pair(wait)) record(std::move(*pair));
    }
    // The last pair can come before its shot has finished (its falling edges): let the trigger
    // play its shots to the end rather than cut one short.
    const auto played = Clock::now() + period + 1s;
    while (!stop_ && config_.pair_count && trigger_->running() && Clock::now() < played) {
      std::this_thread::sleep_for(2ms);
    }
    env_.state->finishing();
    stop_devices();
    drain_after_stop();
    account_for_the_last_triggers();
  } catch (const std::exception& e) {
    acquisition_error_ = e.what();
    stop_devices();
    try {
      take_drops();
    } catch (const std::exception&) {
    }
  }
  // A stop hands the waiting pairs to no one (they are on disk); a run that ended by itself lets the
  // lanes finish theirs. The preview is for acquiring only.
  for (const auto& lane : lanes_) lane->close(stop_);
  if (preview_queue_) preview_queue_->close_and_clear();
}

// The slow part of a start, on the run's thread while Armed: the processing (weight tables) and
// then the folder. False when the run is not to acquire: stopped meanwhile (Armed → Draining →
// Idle, nothing made) or failed (Error, with the reason; no folder).
bool Run::prepare() {
  setup_started_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
  try {
    check_write_rate();
    // A long setup step says how far it is (status), and gives up at its next report once the run
    // is stopped.
    const SetupProgress progress = [this](const std::string& step, double fraction) {
      {
        std::lock_guard lock(setup_mutex_);
        if (step != setup_step_) setup_step_began_ = std::chrono::steady_clock::now();
        setup_step_ = step;
        setup_fraction_ = fraction;
      }
      if (stop_) throw Cancelled("run " + run_id_ + " stopped while setting up (" + step + ")");
    };
    if (env_.processing) {
      try {
        for (const auto& lane : lanes_) {
          processes_.push_back(env_.processing(config_, calibration_, lane->tier(), progress));
          if (stop_) break;
        }
      } catch (const Cancelled&) {
        if (!stop_) throw;
      }
    }
    if (stop_) {
      env_.state->cancel_start();  // Armed (or Draining after `run stop`) → Idle
      spdlog::info("run {} stopped while armed: nothing recorded, no folder made", run_id_);
      return false;
    }
    if (preview_queue_) {
      const optics::CameraModel camera = optics::load_camera_file(env_.camera_file);
      preview_ = std::make_unique<const PreviewMaker>(
          camera, calibration_.loaded ? *calibration_.loaded : calib::nominal_calibration(camera), config_.preview);
    }
    recorder_ = std::make_unique<run_folder::Writer>(setup_);
    if (!setup_warning_.empty()) recorder_->add_warning(setup_warning_);
    prepared_ = true;
    if (env_.heartbeat) env_.heartbeat();  // the setup's time is not a stalled pipeline
    return true;
  } catch (const std::exception& e) {
    env_.state->fail("run " + run_id_ + ": setting up: " + e.what());
    spdlog::error("run {}: setting up failed, nothing recorded: {}", run_id_, e.what());
    return false;
  }
}

void Run::run() {
  if (!prepare()) {
    try {
      stop_devices();
    } catch (...) {
    }
    finished_ = true;
    return;
  }
  std::string failure;
  try {
    camera_->start();  // before the trigger: its first edge must find the camera running
    env_.state->acquiring();
    std::thread acquisition([this] { acquire(); });
    std::thread preview;
    if (preview_) preview = std::thread([this] { preview_loop(); });
    const auto join_threads = [&] {
      acquisition.join();
      if (preview.joinable()) preview.join();
    };
    try {
      process_lanes();
    } catch (...) {
      request_stop();
      join_threads();
      throw;
    }
    join_threads();
    if (!acquisition_error_.empty()) failure = acquisition_error_;
  } catch (const std::exception& e) {
    failure = e.what();
  }
  const std::uint64_t skipped = lanes_.front()->skipped();
  try {
    recorder_->close(failure.empty() ? (stop_ ? "stopped" : "complete") : "failed: " + failure, fields_made(), skipped,
                     losses(), frames_lost(), lane_counters());
  } catch (const std::exception& e) {
    if (failure.empty()) failure = std::string("closing the run folder: ") + e.what();
  }
  const std::uint64_t lost = frames_lost();
  if (failure.empty()) {
    env_.state->finishing();
    env_.state->drained();
    // Frames in no recorded pair (as the status counts them), said at the end where a log reader
    // looks: a warning when there were any.
    const drivers::TriggerCounters tc = trigger_->counters();
    spdlog::log(
        lost || tc.shots_abandoned ? spdlog::level::warn : spdlog::level::info,
        "run {} ended: {} pairs recorded, {} processed, {} skipped, {} frames lost{}{}", run_id_,
        recorder_->pairs_recorded(), fields_made(), skipped, lost,
        tc.shots_delayed ? ", " + std::to_string(tc.shots_delayed) + " laser shots delayed (playback late)" : "",
        tc.shots_abandoned ? ", " + std::to_string(tc.shots_abandoned) + " laser shots abandoned" : "");
  } else {
    env_.state->fail("run " + run_id_ + ": " + failure);
    spdlog::error("run {} failed after {} pairs recorded ({} frames lost): {}", run_id_, recorder_->pairs_recorded(),
                  lost, failure);
  }
  finished_ = true;
}

// The lanes process the recorded pairs until their queues close: the quality lane on a thread of
// its own, the live lane on the run's. A daemon with no processing stage forgets them as they come.
void Run::process_lanes() {
  if (processes_.size() != lanes_.size()) {
    for (const auto& lane : lanes_) lane->discard_all();
    return;
  }
  std::vector<std::thread> others;
  std::vector<std::exception_ptr> errors(lanes_.size());
  const auto run_lane = [this, &errors](std::size_t i) {
    try {
      Lane& lane = *lanes_[i];
      lane.run(
          processes_[i],
          [this, &lane](const drivers::FramePair& pair, ProcessedPair& result) { output(lane, pair, result); }, stop_);
    } catch (...) {
      errors[i] = std::current_exception();
      request_stop();  // an output that failed (the disk) ends the run, whichever lane met it
    }
  };
  for (std::size_t i = 1; i < lanes_.size(); ++i) others.emplace_back(run_lane, i);
  run_lane(0);
  for (std::thread& t : others) t.join();
  for (const std::exception_ptr& e : errors) {
    if (e) std::rethrow_exception(e);
  }
}

// A lane's field: recorded under its tier (run_folder::Writer keeps the tiers apart), then
// published with its tier, and the volumes when the run asks for them.
void Run::output(const Lane& lane, const drivers::FramePair& pair, ProcessedPair& result) {
  if (result.work) {
    std::lock_guard lock(work_mutex_);
    last_work_.emplace(pair.pair_index, std::move(*result.work));
  }
  result.vectors.dt_s = result.vectors.dt_s > 0 ? result.vectors.dt_s : config_.dt_s;
  recorder_->record_vectors(pair.pair_index, result.vectors, result.flags, lane.tier());
  if (env_.publisher) {
    msg::VectorFieldHeader h;
    h.set_run_id(run_id_);
    h.set_pair_index(pair.pair_index);
    h.set_trigger_index(pair.trigger_index);
    h.set_device_timestamp_ns(pair.a.device_timestamp_ns);
    h.set_host_timestamp_ns(pair.a.host_timestamp_ns);
    h.set_pairs_skipped(lane.skipped());
    h.set_tier(process::tier_name(lane.tier()));
    if (pair.measured) {
      // Laser pulse 1 to now, just before sending, on the trigger's clock
      // (CLOCK_MONOTONIC for gpiod and the real-time sim trigger). A value outside
      // [0, 60) s means another clock (a test trigger's virtual time): left at 0.
      timespec now{};
      clock_gettime(CLOCK_MONOTONIC, &now);
      const double now_ns = double(now.tv_sec) * 1e9 + double(now.tv_nsec);
      const double latency_s = (now_ns - double(pair.measured->pulse1_ns)) * 1e-9;
      if (latency_s >= 0 && latency_s < 60) h.set_trigger_latency_s(latency_s);
    }
    env_.publisher->publish_vectors(h, result.vectors);
    if (config_.publish_volumes) {
      for (auto [volume, name] : {std::pair{&result.volume_a, "A"}, std::pair{&result.volume_b, "B"}}) {
        if (!*volume) continue;
        msg::VolumeHeader vh;
        vh.set_run_id(run_id_);
        vh.set_pair_index(pair.pair_index);
        vh.set_exposure(name);
        vh.set_host_timestamp_ns(pair.a.host_timestamp_ns);
        env_.publisher->publish_volume(vh, **volume);
      }
    }
  }
  if (env_.heartbeat) env_.heartbeat();
}

// While the run acquires: a preview of the newest recorded pair, then a wait of interval_s, until the
// acquisition closes the queue. Made in a low-priority arena: the lanes come first for the cores.
void Run::preview_loop() {
  tbb::task_arena arena(tbb::task_arena::automatic, 1, tbb::task_arena::priority::low);
  const ArenaNiceness niceness(arena, env_.processing_nice);
  const auto interval =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(config_.preview.interval_s));
  bool warned = false;
  while (const std::optional<SharedPair> pair = preview_queue_->take()) {
    try {
      Preview p;
      arena.execute([&] { p = preview_->make(**pair); });
      p.header.set_run_id(run_id_);
      env_.publisher->publish_preview(p.header, p.raw, p.refocused);
      ++previews_published_;
    } catch (const std::exception& e) {
      // Said once: the preview is the operator's aid, the run goes on without it.
      if (!warned)
        spdlog::warn("run {}: pair {}: alignment preview failed: {}", run_id_, (*pair)->pair_index, e.what());
      warned = true;
    }
    if (preview_queue_->wait_closed_for(interval)) break;
  }
}

// Vector fields made by every lane (a pair processed by both lanes counts twice).
std::uint64_t Run::fields_made() const {
  std::uint64_t n = 0;
  for (const auto& lane : lanes_) n += lane->stats().output.processed;
  return n;
}

std::vector<msg::LaneCounters> Run::lane_counters() const {
  std::vector<msg::LaneCounters> out;
  for (const auto& lane : lanes_) out.push_back(lane->counters());
  return out;
}

msg::Losses Run::losses() const {
  const drivers::CameraCounters c = camera_->counters();
  msg::Losses l;
  l.set_frames_never_arrived(c.frames_lost + never_arrived_at_end_);
  l.set_frames_discarded(c.frames_discarded);
  l.set_camera_queue_overflow(c.pairs_overflowed);
  l.set_not_read_out(c.pairs_not_read_out);
  l.set_not_recorded_at_stop(not_recorded_at_stop_);
  l.set_shots_abandoned(trigger_->counters().shots_abandoned);
  const Lane& live = *lanes_.front();
  l.set_live_queue_dropped(live.queue().dropped());
  l.set_processing_failed(live.stats().process.skipped);
  l.set_processing_cancelled(live.stats().process.cancelled);
  l.set_camera_lost(camera_lost_);
  l.set_camera_reconnects(c.reconnects);
  return l;
}

// Every raw frame the camera made that is in no recorded pair.
std::uint64_t Run::frames_lost() const {
  const drivers::CameraCounters c = camera_->counters();
  return c.frames_lost + never_arrived_at_end_ + c.frames_discarded +
         2 * (c.pairs_overflowed + c.pairs_not_read_out + not_recorded_at_stop_ + camera_lost_);
}

void Run::fill_status(msg::Status& s) const {
  s.set_run_id(run_id_);
  s.set_run_dir(dir_.string());
  s.set_run_set_up(prepared_);
  if (!prepared_) {
    if (s.message().empty() && !finished_) {
      const double elapsed =
          double(std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count() -
                 setup_started_ns_) *
          1e-9;
      std::string step;
      double fraction = 0, step_elapsed = 0;
      {
        std::lock_guard lock(setup_mutex_);
        step = setup_step_;
        fraction = setup_fraction_;
        step_elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - setup_step_began_).count();
      }
      const std::string text = step.empty()
                                   ? fmt::format("setting up: processing and weight tables, {:.1f} s so far", elapsed)
                                   : "setting up: " + step + ", " + measured_so_far(fraction, step_elapsed);
      s.set_message(setup_started_ns_ ? text : "setting up");
    }
    return;
  }
  // The counters (reconnects among them) are read before the connection, so a status that
  // counts a reconnect never carries the message of the outage it ended.
  *s.mutable_losses() = losses();
  if (const drivers::CameraStatus cs = camera_->status(); !cs.connected && !finished_) {
    s.set_message("camera lost (" + cs.last_error + "); reconnecting, the run waits up to " +
                  seconds(config_.camera_outage_s));
  }
  s.set_pairs_acquired(pairs_received_);
  s.set_pairs_recorded(recorder_->pairs_recorded());
  s.set_pairs_processed(fields_made());
  s.set_pairs_skipped(lanes_.front()->skipped());
  s.set_frames_lost(frames_lost());
  {
    std::lock_guard lock(warnings_mutex_);
    if (!setup_warning_.empty()) s.add_warnings(setup_warning_);
    for (const auto& [kind, seen] : warnings_) {
      s.add_warnings(kind + ": " + std::to_string(seen.first) + " pair(s), first pair " + std::to_string(seen.second));
    }
  }
  {
    std::lock_guard lock(work_mutex_);
    if (last_work_) {
      const ReconstructionWork& w = last_work_->second;
      msg::ReconstructionWork& m = *s.mutable_reconstruction();
      m.set_pair_index(last_work_->first);
      m.set_voxels(w.voxels);
      for (const std::size_t n : w.live_a) m.add_live_voxels_a(n);
      for (const std::size_t n : w.live_b) m.add_live_voxels_b(n);
      m.set_voxel_updates_skipped(w.updates_skipped);
      m.set_work_pruned(w.work_pruned);
      m.set_black_level_a(w.black_level_a);
      m.set_black_level_b(w.black_level_b);
      m.set_black_level_a_lowest(w.black_level_a_lowest);
      m.set_black_level_a_highest(w.black_level_a_highest);
      m.set_black_level_b_lowest(w.black_level_b_lowest);
      m.set_black_level_b_highest(w.black_level_b_highest);
    }
  }
  if (const auto free = io::free_bytes(recorder_->dir())) s.set_bytes_free(*free);
  s.set_laser_shots_delayed(trigger_->counters().shots_delayed);
  s.set_previews_published(previews_published_);
  // The live lane's stages; every lane's counters beside them.
  const Lane& live = *lanes_.front();
  const PipelineStats& stats = live.stats();
  *s.add_stages() = stats.input.to_message("input", std::uint32_t(live.queue().depth()), live.queue().dropped());
  *s.add_stages() = stats.process.to_message("process", stats.process.in_flight);
  *s.add_stages() = stats.output.to_message("output", 0);
  for (const msg::LaneCounters& lane : lane_counters()) *s.add_lanes() = lane;
}

}  // namespace plenopiv::daemon
