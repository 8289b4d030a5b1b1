// plenopivd for integration tests: the real daemon plus the test camera (test://) and a processing
// stage whose field tells which pair it came from (u = pair index m/s), until the simulated
// camera, core/recon and core/piv are merged.
#include "daemon/daemon_main.hpp"
#include "tests/drivers/test_camera.hpp"

namespace {

plenopiv::daemon::ProcessedPair tagged_field(const plenopiv::drivers::FramePair& pair,
                                             const plenopiv::daemon::CancelFlag&) {
  plenopiv::Grid3 g;
  g.shape = {4, 3, 2};
  g.spacing_mm = {0.5, 0.5, 0.5};
  plenopiv::daemon::ProcessedPair out;
  out.vectors = plenopiv::VectorField(g);
  out.vectors.dt_s = 1e-3;
  for (std::size_t i = 0; i < g.count(); ++i) {
    out.vectors.dx_mm[i] = float(pair.pair_index);  // u = pair index in m/s (dt 1 ms)
    out.vectors.valid[i] = i % 4 != 3;              // 3/4 valid
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  plenopiv::testing_support::register_test_camera(plenopiv::drivers::CameraRegistry::instance());
  plenopiv::daemon::DaemonExtensions extensions;
  extensions.processing = [](const plenopiv::daemon::RunConfig&, const plenopiv::daemon::RunCalibration&) {
    return plenopiv::daemon::ProcessFn(tagged_field);
  };
  extensions.processing_summary = "test stage (u = pair index)";
  return plenopiv::daemon::daemon_main(argc, argv, extensions);
}
