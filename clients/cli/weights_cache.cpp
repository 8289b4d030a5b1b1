// Where `plenopiv process` and `plenopiv reconstruct` keep weight tables between calls, and the
// pair processor `plenopiv process` builds through them.
#include "clients/cli/weights_cache.hpp"

#include <cstdio>
#include <optional>

#include "clients/cli/progress.hpp"

namespace plenopiv::client {

std::filesystem::path weights_cache_folder(const std::string& dir, bool off) {
  if (off) return {};
  const std::filesystem::path folder = dir.empty() ? process::default_cache_folder() : std::filesystem::path(dir);
  if (folder.empty())
    std::fprintf(stderr, "weight tables are not cached: no --cache-dir, PLENOPIV_CACHE_DIR, XDG_CACHE_HOME or HOME\n");
  return folder;
}

std::unique_ptr<process::OperatorCache> weights_cache(const std::string& dir, bool off) {
  const std::filesystem::path folder = weights_cache_folder(dir, off);
  if (folder.empty()) return nullptr;
  return std::make_unique<process::OperatorCache>(1, folder);
}

std::unique_ptr<const process::PairProcessor> make_pair_processor(const optics::CameraModel& camera,
                                                                  const calib::LoadedCalibration& calibration,
                                                                  const process::ProcessSettings& settings,
                                                                  process::OperatorCache* operators) {
  std::optional<Progress> response_progress;  // the depth response simulates and processes pairs first
  if (settings.depth_response_ppm > 0) response_progress.emplace("depth response", "%", 100.0);
  process::ProcessorSetup setup;
  setup.operators = operators;
  setup.progress = [&](double f) {
    if (response_progress) response_progress->update(f);
  };
  auto processor = std::make_unique<const process::PairProcessor>(camera, calibration, settings, setup);
  if (operators || processor->depth_response()) std::fprintf(stderr, "%s\n", processor->setup_note().c_str());
  if (!processor->note().empty()) std::fprintf(stderr, "%s\n", processor->note().c_str());
  std::fprintf(stderr, "%s\n", processor->black_level_note().c_str());
  return processor;
}

}  // namespace plenopiv::client
