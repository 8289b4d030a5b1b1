// Where `plenopiv process` and `plenopiv reconstruct` keep weight tables between calls.
#include "clients/cli/weights_cache.hpp"

#include <cstdio>

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

}  // namespace plenopiv::client
