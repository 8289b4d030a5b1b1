// One run: trigger → camera → recorder (every pair) → live pipeline → publisher, on its own threads.
#include "daemon/run.hpp"

#include <spdlog/spdlog.h>

#include <ctime>

#include "core/base/errors.hpp"
#include "core/optics/camera_file.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/common/driver_errors.hpp"
#include "drivers/trigger/camera_wiring.hpp"
#include "drivers/trigger/trigger_registry.hpp"

namespace plenopiv::daemon {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

Run::Run(RunConfig config, std::string run_id, RunEnvironment env)
    : config_(std::move(config)), run_id_(std::move(run_id)), env_(std::move(env)) {
  const std::string camera_uri =
      config_.camera_uri.empty() ? env_.default_camera_uri : config_.camera_uri;
  const std::string trigger_uri =
      config_.trigger_uri.empty() ? env_.default_trigger_uri : config_.trigger_uri;
  camera_ = drivers::open_camera(camera_uri);
  camera_->configure(drivers::CameraSettings{});
  trigger_ = drivers::open_trigger(trigger_uri);
  const drivers::TriggerInfo trigger_info = trigger_->info();
  trigger_->load(run_schedule(env_.timing, trigger_info, config_.rate_hz, config_.dt_s));
  const drivers::CameraWiring wiring = drivers::wire_camera(*trigger_, *camera_);
  camera_trigger_ = wiring.source;
  camera_->arm(drivers::DoubleExposureSettings{wiring.source, 0.0});
  const drivers::CameraInfo info = camera_->info();
  // Read once, checked against the camera file, and then the same bytes go to the processing and
  // into the run folder: a calibration file replaced later changes neither this run nor its copy.
  RunCalibration calibration;
  if (!env_.calibration_file.empty()) {
    if (env_.camera_file.empty()) {
      throw InputError("calibration_file: " + env_.calibration_file.string() +
                       ": needs camera_file (the camera it was made for)");
    }
    calibration = load_run_calibration(env_.calibration_file, optics::load_camera_file(env_.camera_file));
  }
  Recorder::Setup setup{env_.data_dir, run_id_, &config_, camera_uri, trigger_uri, env_.camera_file,
                        info.vendor + " " + info.model + " " + info.serial, wiring.description,
                        &calibration};
  // Bad processing settings and a bad calibration are refused before the run folder exists.
  if (env_.processing) process_ = env_.processing(config_, calibration);
  recorder_ = std::make_unique<Recorder>(setup);
  spdlog::info("run {}: calibration {}", run_id_, calibration.summary());
  spdlog::info("run {}: {} pairs at {} Hz, dt {} s, from {}, trigger {}, folder {}", run_id_,
               config_.pair_count ? std::to_string(config_.pair_count) : "unlimited",
               config_.rate_hz, config_.dt_s, camera_uri, trigger_uri, recorder_->dir().string());
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

void Run::record(drivers::FramePair pair) {
  attach_shot(pair);
  recorder_->record_pair(pair);  // raw frames first: never dropped once delivered
  ++pairs_received_;
  if (env_.heartbeat) env_.heartbeat();
  mailbox_.push(std::make_shared<const drivers::FramePair>(std::move(pair)));
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
    camera_->stop();
  } catch (const std::exception& e) {
    spdlog::error("run {}: stopping the camera: {}", run_id_, e.what());
  }
}

void Run::acquire() {
  try {
    const auto period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(1.0 / config_.rate_hz));
    const bool software = camera_trigger_ == drivers::TriggerSource::Software;
    trigger_->start(config_.pair_count);  // 0: until stopped
    const auto started = Clock::now();
    auto next_trigger = started;
    std::uint64_t fired = 0;
    std::optional<Clock::time_point> last_shot;  // when the trigger had played all its shots
    while (!stop_) {
      const std::uint64_t received = pairs_received_;
      if (config_.pair_count && received >= config_.pair_count) break;
      const auto now = Clock::now();
      if (config_.duration_s > 0 &&
          now - started >= std::chrono::duration<double>(config_.duration_s)) {
        break;
      }
      if (!trigger_->running() && !last_shot) {
        const std::uint64_t shots = trigger_->counters().shots_fired;
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
        camera_->software_trigger();
        ++fired;
        next_trigger += period;
      }
      // All shots fired and the missing pairs never came (lost frames): end after a grace time.
      if (last_shot && (!software || !more_to_fire) && now - *last_shot > 2 * period + 1s) break;
      const auto wait = software ? std::clamp(std::chrono::duration_cast<std::chrono::milliseconds>(
                                                  next_trigger - Clock::now()),
                                              0ms, 50ms)
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
    // Pairs the camera delivered before it stopped are recorded too.
    while (auto pair = camera_->next_pair(0ms)) record(std::move(*pair));
  } catch (const std::exception& e) {
    acquisition_error_ = e.what();
    stop_devices();
  }
  mailbox_.close();
}

void Run::run() {
  std::string failure;
  try {
    camera_->start();  // before the trigger: its first edge must find the camera running
    env_.state->acquiring();
    std::thread acquisition([this] { acquire(); });
    if (process_) {
      try {
        run_live_pipeline(
            mailbox_, config_.max_pairs_in_flight, process_,
            [this](const drivers::FramePair& pair, ProcessedPair& result) {
              result.vectors.dt_s = result.vectors.dt_s > 0 ? result.vectors.dt_s : config_.dt_s;
              recorder_->record_vectors(pair.pair_index, result.vectors);
              if (env_.publisher) {
                msg::VectorFieldHeader h;
                h.set_run_id(run_id_);
                h.set_pair_index(pair.pair_index);
                h.set_trigger_index(pair.trigger_index);
                h.set_device_timestamp_ns(pair.a.device_timestamp_ns);
                h.set_host_timestamp_ns(pair.a.host_timestamp_ns);
                h.set_pairs_skipped(stats_.input.skipped + stats_.process.skipped);
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
                  for (auto [volume, name] : {std::pair{&result.volume_a, "A"},
                                              std::pair{&result.volume_b, "B"}}) {
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
            },
            stats_);
      } catch (...) {
        request_stop();
        acquisition.join();
        throw;
      }
    } else {
      std::uint64_t skipped = 0;
      while (mailbox_.take(skipped)) {
      }
    }
    acquisition.join();
    if (!acquisition_error_.empty()) failure = acquisition_error_;
  } catch (const std::exception& e) {
    failure = e.what();
  }
  const std::uint64_t skipped = stats_.input.skipped + stats_.process.skipped;
  try {
    recorder_->close(failure.empty() ? (stop_ ? "stopped" : "complete") : "failed: " + failure,
                     stats_.output.processed, skipped);
  } catch (const std::exception& e) {
    if (failure.empty()) failure = std::string("closing the run folder: ") + e.what();
  }
  if (failure.empty()) {
    env_.state->finishing();
    env_.state->drained();
    // Frames in no recorded pair (as the status counts them), said at the end where a log reader
    // looks: a warning when there were any.
    const drivers::CameraCounters c = camera_->counters();
    const std::uint64_t lost = c.frames_lost + c.frames_discarded;
    spdlog::log(lost ? spdlog::level::warn : spdlog::level::info,
                "run {} ended: {} pairs recorded, {} processed, {} skipped, {} frames lost", run_id_,
                recorder_->pairs_recorded(), stats_.output.processed.load(), skipped, lost);
  } else {
    env_.state->fail("run " + run_id_ + ": " + failure);
    spdlog::error("run {} failed: {}", run_id_, failure);
  }
  finished_ = true;
}

void Run::fill_status(msg::Status& s) const {
  s.set_run_id(run_id_);
  s.set_run_dir(recorder_->dir().string());
  const drivers::CameraCounters c = camera_->counters();
  s.set_pairs_acquired(pairs_received_);
  s.set_pairs_recorded(recorder_->pairs_recorded());
  s.set_pairs_processed(stats_.output.processed);
  s.set_pairs_skipped(stats_.input.skipped + stats_.process.skipped);
  // Every frame that is in no delivered pair: never arrived, or arrived and was discarded
  // (incomplete, or its partner missing or late). Incomplete frames are among the discarded.
  s.set_frames_lost(c.frames_lost + c.frames_discarded);
  *s.add_stages() = stats_.input.to_message("input", std::uint32_t(mailbox_.depth()));
  *s.add_stages() = stats_.process.to_message("process", stats_.process.in_flight);
  *s.add_stages() = stats_.output.to_message("output", 0);
}

}  // namespace plenopiv::daemon
