// Writes a file under a temporary name and renames it when complete: no half-written outputs.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

namespace plenopiv::io {

// Calls `write(temporary_path)`, flushes the file to the disk, renames it to `path` and flushes
// the folder (fsync both): once this returns the file survives a power cut, and until then `path`
// is left as it was. If anything fails the temporary file is removed; an InputError from `write`
// passes through, anything else becomes std::runtime_error naming `path`, and a full disk reads
// "no space left on device" with the space left in the folder. The folder must exist.
// `sync_folder` false leaves the folder's flush to the caller (sync_folder()), who writes several
// files into one folder and flushes it once for all of them.
void write_atomically(const std::filesystem::path& path, const std::function<void(const std::filesystem::path&)>& write,
                      bool sync_folder = true);

// write_atomically for a file whose whole content is `bytes` (text or binary).
void write_text_atomically(const std::filesystem::path& path, const std::string& bytes);

// Flushes a folder's entries (new and renamed files) to the disk; std::runtime_error naming it.
void sync_folder(const std::filesystem::path& folder);

// Bytes free for an unprivileged writer on the file system holding `folder`; nullopt if unknown.
std::optional<std::uint64_t> free_bytes(const std::filesystem::path& folder);

}  // namespace plenopiv::io
