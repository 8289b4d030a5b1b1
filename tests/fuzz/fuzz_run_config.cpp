// Fuzz target: run.yaml as a start request brings it (daemon/run_config), and the processing keys
// the run folder keeps from it (process.yaml), read back by core/process as `plenopiv process --run`
// reads them: an accepted run's process.yaml must read back as the same volume.
#include <cmath>

#include "core/process/process.hpp"
#include "daemon/run_config.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  daemon::RunConfig config;
  try {
    config = daemon::parse_run_config(fuzzing::as_text(data, size), "start request");
  } catch (const InputError& e) {
    fuzzing::require_names(e, "start request");
    return 0;
  }
  // Whether dt fits the rate's period is the trigger sequencer's to check at start, with the rig's
  // limits (daemon/run_config keeps the numbers sane only).
  fuzzing::require(config.rate_hz > 0 && config.rate_hz <= 1000 && config.dt_s > 0 && std::isfinite(config.dt_s),
                   "an accepted run config has an impossible rate or dt");
  const Grid3 g = config.volume_grid();
  for (int a = 0; a < 3; ++a) fuzzing::require(g.shape[a] >= 1, "an accepted run config has an empty volume axis");
  const Grid3 with_guard = config.spec.full.reconstruction_grid();
  fuzzing::require(with_guard.shape[2] >= g.shape[2] && with_guard.shape[2] <= 300000,
                   "an accepted run config's depth guard is not a sane number of slices");
  fuzzing::require(config.live_queue >= 1 && config.max_pairs_in_flight >= 1, "accepted run config: no queue");
  // What `plenopiv process --run` reads: the same processing spec, never a refusal.
  const auto path = fuzzing::input_file(reinterpret_cast<const std::uint8_t*>(config.process_yaml().data()),
                                        config.process_yaml().size(), "process.yaml");
  try {
    const process::ProcessSpec again = process::load_process_spec(path);
    fuzzing::require(again.full.grid.shape == g.shape, "process.yaml reads back as another volume");
  } catch (const InputError& e) {
    fuzzing::broken(std::string("an accepted run's process.yaml is refused: ") + e.what());
  }
  return 0;
}
