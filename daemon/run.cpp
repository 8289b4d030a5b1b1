// One run: camera → recorder (every pair) → live pipeline → publisher, on its own threads.
#include "daemon/run.hpp"

#include <spdlog/spdlog.h>

#include "core/base/errors.hpp"
#include "drivers/camera/camera_registry.hpp"

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
  // Software triggers paced at rate_hz until the trigger drivers fire the laser and camera lines.
  camera_->arm(drivers::DoubleExposureSettings{drivers::TriggerSource::Software, 0.0});
  const drivers::CameraInfo info = camera_->info();
  Recorder::Setup setup{env_.data_dir, run_id_, &config_, camera_uri, trigger_uri, env_.camera_file,
                        info.vendor + " " + info.model + " " + info.serial};
  recorder_ = std::make_unique<Recorder>(setup);
  if (env_.processing) process_ = env_.processing(config_);
  spdlog::info("run {}: {} pairs at {} Hz from {}, folder {}", run_id_,
               config_.pair_count ? std::to_string(config_.pair_count) : "unlimited",
               config_.rate_hz, camera_uri, recorder_->dir().string());
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
  recorder_->record_pair(pair);  // raw frames first: never dropped once delivered
  ++pairs_received_;
  if (env_.heartbeat) env_.heartbeat();
  mailbox_.push(std::make_shared<const drivers::FramePair>(std::move(pair)));
}

void Run::acquire() {
  try {
    const auto period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(1.0 / config_.rate_hz));
    const auto started = Clock::now();
    auto next_trigger = started;
    std::uint64_t fired = 0;
    auto last_fired = started;
    while (!stop_) {
      const std::uint64_t received = pairs_received_;
      if (config_.pair_count && received >= config_.pair_count) break;
      const auto now = Clock::now();
      if (config_.duration_s > 0 &&
          now - started >= std::chrono::duration<double>(config_.duration_s)) {
        break;
      }
      const bool more_to_fire = config_.pair_count == 0 || fired < config_.pair_count;
      if (more_to_fire && now >= next_trigger) {
        camera_->software_trigger();
        ++fired;
        last_fired = now;
        next_trigger += period;
      }
      // All triggers fired and the missing pairs never came (lost frames): end after a grace time.
      if (!more_to_fire && now - last_fired > 2 * period + 1s) break;
      const auto wait = std::clamp(std::chrono::duration_cast<std::chrono::milliseconds>(
                                       next_trigger - Clock::now()),
                                   0ms, 50ms);
      if (auto pair = camera_->next_pair(wait)) record(std::move(*pair));
    }
    env_.state->finishing();
    camera_->stop();
    // Pairs the camera delivered before it stopped are recorded too.
    while (auto pair = camera_->next_pair(0ms)) record(std::move(*pair));
  } catch (const std::exception& e) {
    acquisition_error_ = e.what();
    try {
      camera_->stop();
    } catch (const std::exception&) {
    }
  }
  mailbox_.close();
}

void Run::run() {
  std::string failure;
  try {
    camera_->start();
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
    spdlog::info("run {} ended: {} pairs recorded, {} processed, {} skipped", run_id_,
                 recorder_->pairs_recorded(), stats_.output.processed.load(), skipped);
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
  s.set_frames_lost(c.frames_lost + c.frames_incomplete);
  *s.add_stages() = stats_.input.to_message("input", std::uint32_t(mailbox_.depth()));
  *s.add_stages() = stats_.process.to_message("process", stats_.process.in_flight);
  *s.add_stages() = stats_.output.to_message("output", 0);
}

}  // namespace plenopiv::daemon
