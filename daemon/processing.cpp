// The live processing stage: a thin adapter from recorded pairs to process::PairProcessor.
#include "daemon/processing.hpp"

#include <spdlog/spdlog.h>

#include <memory>

#include "core/base/errors.hpp"
#include "core/base/memory.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/process/pair_processor.hpp"

namespace plenopiv::daemon {

ProcessFactory plenoptic_processing(const optics::CameraModel& camera) {
  return [camera](const RunConfig& config, const RunCalibration& calibration) -> ProcessFn {
    const process::ProcessSettings& settings = config.spec.full;
    // A run's volume is refused before any table is built when the pairs it keeps in flight would not
    // fit this machine.
    const Grid3 g = settings.reconstruction_grid();
    require_memory(settings.peak_bytes_per_pair() * config.max_pairs_in_flight,
                   "processing " + std::to_string(config.max_pairs_in_flight) + " pair(s) at once on a " +
                       std::to_string(g.shape[0]) + " x " + std::to_string(g.shape[1]) + " x " +
                       std::to_string(g.shape[2]) + " voxel volume (volume, max_pairs_in_flight)");
    auto processor = std::make_shared<const process::PairProcessor>(
        camera, calibration.loaded ? *calibration.loaded : calib::nominal_calibration(camera), settings);
    spdlog::info("run processing: calibration {}; {}", calibration.summary(),
                 processor->note().empty() ? "frames reconstructed on raw pixels" : processor->note());
    const bool keep_volumes = config.publish_volumes;
    return [processor, keep_volumes](const drivers::FramePair& pair, const CancelFlag& cancel) {
      process::PairOptions options;
      if (pair.measured) options.measured_dt_s = pair.measured->dt_s();
      // Called after every MART iteration and correlation pass: a stopping run gives up there.
      options.progress = [&cancel](const std::string&, double) {
        if (cancel) throw Cancelled("run stopping");
      };
      process::PairResult r = processor->process(pair.a.image, pair.b.image, options);
      ProcessedPair out;
      out.vectors = std::move(r.correlation.field);
      if (keep_volumes) {
        out.volume_a = std::move(r.volume_a);
        out.volume_b = std::move(r.volume_b);
      }
      return out;
    };
  };
}

}  // namespace plenopiv::daemon
