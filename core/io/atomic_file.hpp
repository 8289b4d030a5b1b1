// Writes a file under a temporary name and renames it when complete: no half-written outputs.
#pragma once

#include <filesystem>
#include <functional>

namespace plenopiv::io {

// Calls `write(temporary_path)`, then renames the temporary file to `path`. If `write` throws,
// the temporary file is removed and `path` is left as it was. The folder must exist.
void write_atomically(const std::filesystem::path& path,
                      const std::function<void(const std::filesystem::path&)>& write);

}  // namespace plenopiv::io
