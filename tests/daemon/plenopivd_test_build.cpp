// plenopivd for integration tests: the real daemon plus the test camera (test://) and a processing
// stage whose field tells which pair and tier it came from (u = pair index m/s; the live tier's
// fields all valid, the full tier's 3/4), and which can be made slow on the full tier
// (PLENOPIV_TEST_FULL_TIER_MS: milliseconds per pair) to load the quality lane.
#include <chrono>
#include <cstdlib>
#include <thread>

#include "core/base/errors.hpp"
#include "daemon/daemon_main.hpp"
#include "tests/drivers/test_camera.hpp"

namespace {

plenopiv::daemon::ProcessedPair tagged_field(const plenopiv::drivers::FramePair& pair, plenopiv::process::Tier tier) {
  plenopiv::Grid3 g;
  g.shape = {4, 3, 2};
  g.spacing_mm = {0.5, 0.5, 0.5};
  plenopiv::daemon::ProcessedPair out;
  out.vectors = plenopiv::VectorField(g);
  out.vectors.dt_s = 1e-3;
  for (std::size_t i = 0; i < g.count(); ++i) {
    out.vectors.dx_mm[i] = float(pair.pair_index);  // u = pair index in m/s (dt 1 ms)
    out.vectors.valid[i] = tier == plenopiv::process::Tier::live || i % 4 != 3;
  }
  return out;
}

// The full tier's time per pair, taking a step every 10 ms as real processing does.
void full_tier_delay(const plenopiv::daemon::PairSteps& steps) {
  const char* text = std::getenv("PLENOPIV_TEST_FULL_TIER_MS");
  const int ms = text ? std::atoi(text) : 0;
  for (int waited = 0; waited < ms; waited += 10) {
    steps.step();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

}  // namespace

int main(int argc, char** argv) {
  plenopiv::testing_support::register_test_camera(plenopiv::drivers::CameraRegistry::instance());
  plenopiv::daemon::DaemonExtensions extensions;
  extensions.processing = [](const plenopiv::daemon::RunConfig&, const plenopiv::daemon::RunCalibration&,
                             plenopiv::process::Tier tier, const plenopiv::daemon::SetupProgress&) {
    return plenopiv::daemon::ProcessFn(
        [tier](const plenopiv::drivers::FramePair& pair, const plenopiv::daemon::PairSteps& steps) {
          if (tier == plenopiv::process::Tier::full) full_tier_delay(steps);
          return tagged_field(pair, tier);
        });
  };
  extensions.processing_summary = "test stage (u = pair index)";
  return plenopiv::daemon::daemon_main(argc, argv, extensions);
}
