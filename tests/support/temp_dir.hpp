// A scratch folder per test process: ctest runs test cases in parallel processes.
#pragma once

#include <unistd.h>

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <set>
#include <string>

namespace plenopiv::testing_support {

namespace detail {
// The scratch folders this process made, removed when it exits with every test passed: a suite
// that CI runs again and again must not leave gigabytes behind. After a failure they stay for a
// look (their paths are in the failing test's output).
struct ScratchFolders {
  std::mutex mutex;
  std::set<std::filesystem::path> made;
  pid_t owner = ::getpid();

  static ScratchFolders& instance() {
    // Never destroyed: the exit handler below runs after static destructors may have.
    static ScratchFolders* folders = [] {
      auto* f = new ScratchFolders;
      // gtest's UnitTest made before the handler is registered is destroyed after it runs.
      (void)::testing::UnitTest::GetInstance();
      std::atexit([] {
        ScratchFolders& f = instance();
        if (::getpid() != f.owner || ::testing::UnitTest::GetInstance()->Failed()) return;
        std::error_code ignored;
        for (const auto& dir : f.made) std::filesystem::remove_all(dir, ignored);
      });
      return f;
    }();
    return *folders;
  }
};
}  // namespace detail

// <tmp>/plenopiv-<area>-<pid>, emptied on this process's first use: a folder of that name left by an
// earlier process with the same (recycled) pid must not hand this one its files. Removed at exit
// unless a test failed.
inline std::filesystem::path temp_dir(const std::string& area) {
  const auto dir = std::filesystem::temp_directory_path() / ("plenopiv-" + area + "-" + std::to_string(::getpid()));
  detail::ScratchFolders& folders = detail::ScratchFolders::instance();
  std::lock_guard lock(folders.mutex);
  if (folders.made.insert(dir).second) std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// How many entries of `folder` have names starting with `prefix`; 0 for a folder that does not exist.
inline std::size_t entries_named(const std::filesystem::path& folder, const std::string& prefix) {
  std::size_t n = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(folder, ec))
    n += e.path().filename().string().starts_with(prefix);
  return n;
}

// A control endpoint of its own for a daemon a test starts: an ipc:// socket file in this
// process's scratch folder (the daemon's local default kind; tcp:// needs CURVE).
inline std::string ipc_endpoint(const std::string& name) {
  static int counter = 0;
  return "ipc://" + (temp_dir("ipc") / (name + "-" + std::to_string(counter++))).string();
}

}  // namespace plenopiv::testing_support
