// The live processing stage: raw pair → process::process_pair (MART of A and B, 3D correlation).
#include "daemon/processing.hpp"

#include <spdlog/spdlog.h>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/process/process.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::daemon {
namespace {

ImageF to_float(const ImageU16& image) {
  ImageF out(image.width, image.height);
  for (std::size_t i = 0; i < image.size(); ++i) out.pixels[i] = float(image.pixels[i]);
  return out;
}

}  // namespace

ProcessFactory plenoptic_processing(const optics::CameraModel& camera) {
  return [camera](const RunConfig& config, const RunCalibration& calibration) -> ProcessFn {
    // The run's settings go through the text the run folder keeps (process.yaml), so the live
    // stage and `plenopiv process --run` read exactly the same settings the same way.
    const process::ProcessSettings settings =
        process::process_settings_from(YamlMap(load_yaml_text(config.process_yaml(), "run config"), "run config"));
    // Built once per run, shared read-only by the concurrent pairs. PairOperator resamples the
    // frames onto an axis-aligned lattice when the array is not separable (a calibrated array is
    // always rotated a little; never the nominal lattice): said in the log when it does.
    std::shared_ptr<const process::PairOperator> op;
    if (calibration.loaded) {
      op = std::make_shared<const process::PairOperator>(camera, calibration.loaded->lenses,
                                                         calibration.loaded->white_correction, settings);
    } else {
      const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
      op = std::make_shared<const process::PairOperator>(camera, lenses, recon::geometric_white_image(camera, lenses),
                                                         settings);
    }
    spdlog::info("run processing: calibration {}; {}", calibration.summary(),
                 op->note().empty() ? "frames reconstructed on raw pixels" : op->note());
    const bool keep_volumes = config.publish_volumes;
    return [op, settings, keep_volumes](const drivers::FramePair& pair) {
      process::ProcessSettings s = settings;
      if (pair.measured && pair.measured->dt_s() > 0) s.correlation.dt_s = pair.measured->dt_s();
      process::PairResult r = process::process_pair(*op, to_float(pair.a.image), to_float(pair.b.image), s);
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
