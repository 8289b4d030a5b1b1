// The live processing stage: raw pair → MART volumes A and B (core/recon) → 3D correlation (core/piv).
#include "daemon/processing.hpp"

#include <unistd.h>

#include <atomic>
#include <fstream>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/piv/multipass.hpp"
#include "core/piv/settings.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::daemon {
namespace {

recon::MartSettings mart_settings(const YAML::Node& section) {
  const YamlMap map(section, "run config", "reconstruction");
  map.reject_unknown({"iterations", "mu", "start", "noise_threshold", "dark_weight_cutoff",
                      "convergence"});
  recon::MartSettings s;
  const long long iterations = map.integer_or("iterations", s.iterations);
  if (iterations < 1 || iterations > 1000) map.fail("iterations", "must be between 1 and 1000");
  s.iterations = int(iterations);
  s.mu = map.number_or("mu", s.mu);
  if (!(s.mu > 0 && s.mu <= 1)) map.fail("mu", "must be in (0, 1]");
  s.start = map.choice_or("start", {"mlos", "ones"}, "mlos") == "mlos" ? recon::MartStart::mlos
                                                                        : recon::MartStart::ones;
  s.noise_threshold = float(map.number_or("noise_threshold", s.noise_threshold));
  s.dark_weight_cutoff = map.number_or("dark_weight_cutoff", s.dark_weight_cutoff);
  s.convergence = map.number_or("convergence", s.convergence);
  return s;
}

// core/piv reads its settings from a file; the section is handed to it as one, so the daemon
// and `plenopiv correlate` accept exactly the same keys.
piv::CorrelationSettings correlation_settings(const YAML::Node& section, double dt_s) {
  static std::atomic<int> counter{0};
  const auto path = std::filesystem::temp_directory_path() /
                    ("plenopivd-correlation-" + std::to_string(::getpid()) + "-" +
                     std::to_string(counter++) + ".yaml");
  {
    YAML::Node copy = YAML::Clone(section);
    if (!copy["dt_s"]) copy["dt_s"] = dt_s;
    std::ofstream out(path);
    out << copy;
  }
  try {
    piv::CorrelationSettings s = piv::load_correlation_settings(path);
    std::filesystem::remove(path);
    return s;
  } catch (const InputError& e) {
    std::filesystem::remove(path);
    throw InputError(std::string("run config: correlation: ") + e.what());
  }
}

ImageF to_float(const ImageU16& image) {
  ImageF out(image.width, image.height);
  for (std::size_t i = 0; i < image.size(); ++i) out.pixels[i] = float(image.pixels[i]);
  return out;
}

}  // namespace

ProcessFactory plenoptic_processing(const optics::CameraModel& camera) {
  return [camera](const RunConfig& config) -> ProcessFn {
    const recon::MartSettings mart = mart_settings(config.reconstruction);
    const piv::CorrelationSettings correlation =
        correlation_settings(config.correlation, config.dt_s);
    const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
    auto op = std::make_shared<const recon::WeightingOperator>(
        camera, lenses, config.volume_grid(), recon::geometric_white_image(camera, lenses));
    const bool keep_volumes = config.publish_volumes;
    return [op, mart, correlation, keep_volumes](const drivers::FramePair& pair) {
      const ImageF a = to_float(pair.a.image), b = to_float(pair.b.image);
      recon::validate_image(a, *op, "frame A");
      recon::validate_image(b, *op, "frame B");
      ProcessedPair out;
      Volume va = recon::reconstruct(*op, a, mart).volume;
      Volume vb = recon::reconstruct(*op, b, mart).volume;
      piv::CorrelationSettings s = correlation;
      if (pair.measured && pair.measured->dt_s() > 0) s.dt_s = pair.measured->dt_s();
      out.vectors = piv::correlate_volumes(va, vb, s).field;
      if (keep_volumes) {
        out.volume_a = std::move(va);
        out.volume_b = std::move(vb);
      }
      return out;
    };
  };
}

}  // namespace plenopiv::daemon
