// Where `plenopiv process` and `plenopiv reconstruct` keep weight tables between calls, and the
// pair processor `plenopiv process` builds through them.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_model.hpp"
#include "core/process/operator_cache.hpp"
#include "core/process/pair_processor.hpp"

namespace plenopiv::client {

// The folder for weight tables: `dir` (--cache-dir), else process::default_cache_folder(); empty
// with --no-cache (`off`), or when no folder is known (then said on stderr: the tables are built).
std::filesystem::path weights_cache_folder(const std::string& dir, bool off);

// An operator cache over that folder's files (one operator kept in memory), or null when there is
// no folder: a command builds its operator through it (process::PairProcessor), the same either way.
std::unique_ptr<process::OperatorCache> weights_cache(const std::string& dir, bool off);

// The pair processor of `plenopiv process` and `process --run`, built through `operators` (null:
// built): a progress bar while it measures the depth response (settings.depth_response_ppm above
// 0), then on stderr where its tables came from (with a cache) and the response's range, and the
// operator's note.
std::unique_ptr<const process::PairProcessor> make_pair_processor(const optics::CameraModel& camera,
                                                                  const calib::LoadedCalibration& calibration,
                                                                  const process::ProcessSettings& settings,
                                                                  process::OperatorCache* operators);

}  // namespace plenopiv::client
