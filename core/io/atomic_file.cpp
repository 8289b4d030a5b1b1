// Writes a file under a temporary name and renames it when complete: no half-written outputs.
#include "core/io/atomic_file.hpp"

#include <fcntl.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <system_error>

#include "core/base/errors.hpp"

namespace plenopiv::io {
namespace {

// Flushes a file or folder to the disk (fsync); false with errno set when it cannot.
bool sync_path(const std::filesystem::path& path, bool folder) {
  const int fd = ::open(path.c_str(), (folder ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  const int saved = errno;
  ::close(fd);
  errno = saved;
  return ok;
}

std::string space_text(double bytes) {
  char text[64];
  std::snprintf(text, sizeof text, "%.3g MB", bytes / 1e6);
  return text;
}

// Whether a failed write most likely ran out of space: the errno says so, or the folder's file
// system has (almost) nothing left.
bool out_of_space(const std::filesystem::path& folder, int error) {
  if (error == ENOSPC || error == EDQUOT) return true;
  const auto free = free_bytes(folder);
  return free && *free < 64 * 1024;
}

[[noreturn]] void fail_writing(const std::filesystem::path& path, const std::filesystem::path& folder, int error,
                               const std::string& detail) {
  if (out_of_space(folder, error)) {
    const auto free = free_bytes(folder);
    throw std::runtime_error(path.string() + ": no space left on device (" +
                             (free ? space_text(double(*free)) : std::string("nothing")) + " free in " +
                             folder.string() + "); nothing was written under this name");
  }
  throw std::runtime_error(path.string() + ": " + detail);
}

}  // namespace

std::optional<std::uint64_t> free_bytes(const std::filesystem::path& folder) {
  struct statvfs s {};
  if (::statvfs(folder.c_str(), &s) != 0) return std::nullopt;
  return std::uint64_t(s.f_bavail) * std::uint64_t(s.f_frsize);
}

void write_text_atomically(const std::filesystem::path& path, const std::string& bytes) {
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
    out.close();
    if (!out) throw std::runtime_error(path.string() + ": cannot write");
  });
}

void sync_folder(const std::filesystem::path& folder) {
  if (!sync_path(folder, true)) {
    const int error = errno;
    fail_writing(folder, folder, error, std::string("cannot flush the folder: ") + std::strerror(error));
  }
}

void write_atomically(const std::filesystem::path& path, const std::function<void(const std::filesystem::path&)>& write,
                      bool sync_folder) {
  static std::atomic<unsigned> counter{0};
  if (!path.has_filename()) throw InputError("'" + path.string() + "': not a file name to write");
  const std::filesystem::path folder = path.has_parent_path() ? path.parent_path() : ".";
  if (!std::filesystem::is_directory(folder)) {
    throw InputError(path.string() + ": cannot write: folder " + folder.string() + " does not exist");
  }
  // Same folder as the target, so the rename stays on one file system and is atomic.
  const std::filesystem::path tmp = folder / ("." + path.filename().string() + ".tmp-" + std::to_string(::getpid()) +
                                              "-" + std::to_string(counter++));
  const auto discard = [&] {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
  };
  errno = 0;
  try {
    write(tmp);
  } catch (const InputError&) {
    discard();
    throw;
  } catch (const std::exception& e) {
    const int error = errno;
    discard();
    fail_writing(path, folder, error, e.what());
  }
  // The data reaches the disk before the name does, and the new name before we return: after a
  // power cut the file is either the old one or the whole new one.
  if (!sync_path(tmp, false)) {
    const int error = errno;
    discard();
    fail_writing(path, folder, error, std::string("cannot flush the written file: ") + std::strerror(error));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int error = errno;
    discard();
    fail_writing(path, folder, error,
                 std::string("cannot rename the finished file into place: ") + std::strerror(error));
  }
  if (sync_folder && !sync_path(folder, true)) {
    const int error = errno;
    fail_writing(path, folder, error, std::string("cannot flush its folder: ") + std::strerror(error));
  }
}

}  // namespace plenopiv::io
