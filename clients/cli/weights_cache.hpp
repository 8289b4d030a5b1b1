// Where `plenopiv process` and `plenopiv reconstruct` keep weight tables between calls.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "core/process/operator_cache.hpp"

namespace plenopiv::client {

// The folder for weight tables: `dir` (--cache-dir), else process::default_cache_folder(); empty
// with --no-cache (`off`), or when no folder is known (then said on stderr: the tables are built).
std::filesystem::path weights_cache_folder(const std::string& dir, bool off);

// An operator cache over that folder's files (one operator kept in memory), or null when there is
// no folder: a command builds its operator through it (process::PairProcessor), the same either way.
std::unique_ptr<process::OperatorCache> weights_cache(const std::string& dir, bool off);

}  // namespace plenopiv::client
