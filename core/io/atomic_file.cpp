// Writes a file under a temporary name and renames it when complete: no half-written outputs.
#include "core/io/atomic_file.hpp"

#include <unistd.h>

#include <atomic>
#include <string>
#include <system_error>

#include "core/base/errors.hpp"

namespace plenopiv::io {

void write_atomically(const std::filesystem::path& path,
                      const std::function<void(const std::filesystem::path&)>& write) {
  static std::atomic<unsigned> counter{0};
  const std::filesystem::path folder = path.has_parent_path() ? path.parent_path() : ".";
  if (!std::filesystem::is_directory(folder)) {
    throw InputError(path.string() + ": cannot write: folder " + folder.string() + " does not exist");
  }
  // Same folder as the target, so the rename stays on one file system and is atomic.
  const std::filesystem::path tmp =
      folder / ("." + path.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                std::to_string(counter++));
  try {
    write(tmp);
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw;
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw InputError(path.string() + ": cannot rename the finished file into place: " + ec.message());
  }
}

}  // namespace plenopiv::io
