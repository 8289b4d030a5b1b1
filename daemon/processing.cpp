// The live processing stage: a thin adapter from recorded pairs to process::PairProcessor.
#include "daemon/processing.hpp"

#include <spdlog/fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <optional>
#include <string>

#include "core/base/memory.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/process/pair_processor.hpp"

namespace plenopiv::daemon {
namespace {

ReconstructionWork reconstruction_work(const process::PairResult& r) {
  ReconstructionWork w;
  w.voxels = r.skipped_a.voxels;
  for (const auto& it : r.iterations_a) w.live_a.push_back(it.live_voxels);
  for (const auto& it : r.iterations_b) w.live_b.push_back(it.live_voxels);
  // Over both frames' iterations; a pair whose frames lit no voxel ran none and skipped everything.
  const double all =
      double(r.skipped_a.voxels) * r.skipped_a.iterations + double(r.skipped_b.voxels) * r.skipped_b.iterations;
  w.updates_skipped = all > 0 ? 1.0 - double(r.skipped_a.voxel_updates + r.skipped_b.voxel_updates) / all : 1.0;
  const double unpruned = r.skipped_a.work_unpruned + r.skipped_b.work_unpruned;
  w.work_pruned = unpruned > 0 ? 1.0 - (r.skipped_a.work_done + r.skipped_b.work_done) / unpruned : 0.0;
  w.black_level_a = r.black_level_a.median();
  w.black_level_b = r.black_level_b.median();
  w.black_level_a_lowest = r.black_level_a.lowest();
  w.black_level_a_highest = r.black_level_a.highest();
  w.black_level_b_lowest = r.black_level_b.lowest();
  w.black_level_b_highest = r.black_level_b.highest();
  return w;
}

}  // namespace

ProcessFactory plenoptic_processing(const optics::CameraModel& camera, const std::filesystem::path& response_folder) {
  // Kept for the factory's life (the daemon's): runs with the same geometry share their operator.
  auto operators = std::make_shared<process::OperatorCache>();
  return [camera, operators, response_folder](const RunConfig& config, const RunCalibration& calibration,
                                              process::Tier tier, const SetupProgress& progress) -> ProcessFn {
    const process::ProcessSettings& settings = config.spec.settings(tier, "run config");
    // A run's volumes are refused before any table is built when the pairs its lanes keep in flight
    // would not fit this machine.
    const process::ProcessSettings& live = config.spec.settings(config.live_lane_tier(), "run config");
    const Grid3 g = live.reconstruction_grid();
    const int quality = config.quality.on() ? QualityLane::kPairsInFlight : 0;
    require_memory(
        live.peak_bytes_per_pair() * config.max_pairs_in_flight + config.spec.full.peak_bytes_per_pair() * quality,
        "processing " + std::to_string(config.max_pairs_in_flight) + " pair(s) at once on a " +
            std::to_string(g.shape[0]) + " x " + std::to_string(g.shape[1]) + " x " + std::to_string(g.shape[2]) +
            " voxel volume (volume, max_pairs_in_flight)" +
            (quality ? " beside the quality lane's pair on the full settings' volume" : ""));
    // The live lane's depth response is measured now, while Armed: its pairs need it from the first.
    // The quality lane's is measured by its first pair, so that the run acquires meanwhile: that
    // pair waits while the live lane is busy, as its processing does, and gives up when the run stops.
    const bool live_lane = tier == config.live_lane_tier();
    const std::string step = "depth response of the " + std::string(process::tier_name(tier)) + " tier";
    if (progress && live_lane && settings.depth_response_ppm > 0) progress(step, 0.0);
    process::ProcessorSetup setup;
    setup.operators = operators.get();
    setup.progress = [&](double fraction) {
      if (progress) progress(step, fraction);
    };
    setup.response_folder = response_folder;
    setup.defer_depth_response = !live_lane;
    auto processor = std::make_shared<const process::PairProcessor>(
        camera, calibration.loaded ? *calibration.loaded : calib::nominal_calibration(camera), settings, setup);
    spdlog::info("run processing, {} tier: calibration {}; {}; {}; {}", process::tier_name(tier), calibration.summary(),
                 processor->setup_note(),
                 processor->note().empty() ? "frames reconstructed on raw pixels" : processor->note(),
                 processor->black_level_note());
    // The lane's pairs in flight get their buffers now, while Armed, not beside the recording.
    const int in_flight = live_lane ? config.max_pairs_in_flight : QualityLane::kPairsInFlight;
    const auto t0 = std::chrono::steady_clock::now();
    const std::size_t bytes = processor->reserve_workspaces(in_flight);
    spdlog::info("run processing, {} tier: buffers for {} pair(s) in flight reserved, {:.2f} GB, in {:.1f} s",
                 process::tier_name(tier), in_flight, double(bytes) / 1e9,
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    // Volumes are published from the live lane only (the quality lane's would double the traffic).
    const bool keep_volumes = config.publish_volumes && live_lane;
    // A deferred depth response is said once, by the pair that took it.
    auto response_said = std::make_shared<std::atomic<bool>>(processor->depth_response() != nullptr);
    return [processor, keep_volumes, tier, response_said](const drivers::FramePair& pair, const PairSteps& steps) {
      process::PairOptions options;
      if (pair.measured) options.measured_dt_s = pair.measured->dt_s();
      // Called after every MART iteration and correlation pass: the quality lane waits there while
      // the live lane is busy, and a stopping run gives up there. A deferred depth response (the
      // lane's first pair: minutes at paper scale) is said in the lane's status as it goes.
      std::optional<std::chrono::steady_clock::time_point> response_began;
      options.progress = [&steps, &response_began, tier](const std::string& stage, double fraction) {
        if (stage == process::kDeferredDepthResponseStage) {
          const auto now = std::chrono::steady_clock::now();
          if (!response_began) response_began = now;
          steps.say(
              depth_response_activity(tier, fraction, std::chrono::duration<double>(now - *response_began).count()));
        }
        steps.step();
      };
      process::PairResult r = processor->process(pair.a.image, pair.b.image, options);
      if (processor->depth_response() && !response_said->exchange(true))
        spdlog::info("run processing, {} tier: {}", process::tier_name(tier), processor->depth_response_note());
      ProcessedPair out;
      out.vectors = std::move(r.correlation.field);
      out.flags = std::move(r.correlation.flags);
      out.work = reconstruction_work(r);
      spdlog::debug(
          "pair {}: black level taken off A {}, B {} counts; MART skipped {:.1f} % of the voxel updates ({:.1f} % "
          "of the work pruned); live voxels per iteration A {}, B {}",
          pair.pair_index, r.black_level_a.text(), r.black_level_b.text(), 100 * out.work->updates_skipped,
          100 * out.work->work_pruned, fmt::join(out.work->live_a, " "), fmt::join(out.work->live_b, " "));
      if (keep_volumes) {
        out.volume_a = std::move(r.volume_a);
        out.volume_b = std::move(r.volume_b);
      }
      return out;
    };
  };
}

std::string depth_response_activity(process::Tier tier, double fraction, double elapsed_s) {
  return fmt::format("depth response of the {} tier, {} (its first pair; kept for later runs)",
                     process::tier_name(tier), measured_so_far(fraction, elapsed_s));
}

}  // namespace plenopiv::daemon
