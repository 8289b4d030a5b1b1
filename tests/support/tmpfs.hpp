// Tests: a small tmpfs mounted for the length of a test, to fill a disk for real.
#pragma once

#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

namespace plenopiv::testing_support {

// Mounts a tmpfs of `megabytes` at `dir` (made if missing) and unmounts it when destroyed.
// Mounting needs root (CI runs as root); otherwise `why_not()` says why and the test skips.
class SmallTmpfs {
 public:
  SmallTmpfs(const std::filesystem::path& dir, int megabytes) : dir_(dir) {
    std::filesystem::create_directories(dir_);
    const std::string options = "size=" + std::to_string(megabytes) + "m,mode=0755";
    if (::geteuid() != 0) {
      why_not_ = "needs root to mount a small tmpfs (a disk to fill)";
    } else if (::mount("tmpfs", dir_.c_str(), "tmpfs", 0, options.c_str()) != 0) {
      why_not_ = std::string("cannot mount a tmpfs at ") + dir_.string() + ": " + std::strerror(errno);
    } else {
      mounted_ = true;
    }
  }
  ~SmallTmpfs() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
  }
  SmallTmpfs(const SmallTmpfs&) = delete;
  SmallTmpfs& operator=(const SmallTmpfs&) = delete;

  bool mounted() const { return mounted_; }
  const std::string& why_not() const { return why_not_; }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
  bool mounted_ = false;
  std::string why_not_;
};

}  // namespace plenopiv::testing_support
