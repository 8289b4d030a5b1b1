// Tests: a data folder's run folders, and a run folder's manifest read back as the RunManifest
// message, with its journal applied (run_folder::read_manifest), a test failure, not an exception,
// when it does not read.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <vector>

#include "plenopiv.pb.h"
#include "proto/run_folder.hpp"

namespace plenopiv::testing_support {

// The run folders (run-*) plenopivd made in `data_dir`, sorted by name (their start time).
inline std::vector<std::filesystem::path> run_folders(const std::filesystem::path& data_dir) {
  std::vector<std::filesystem::path> runs;
  for (const auto& e : std::filesystem::directory_iterator(data_dir)) {
    if (e.path().filename().string().starts_with(run_folder::kRunFolderPrefix)) runs.push_back(e.path());
  }
  std::sort(runs.begin(), runs.end());
  return runs;
}

// The one run folder in `data_dir`; a test failure (and an empty path) when there is not exactly one.
inline std::filesystem::path only_run_folder(const std::filesystem::path& data_dir) {
  const std::vector<std::filesystem::path> runs = run_folders(data_dir);
  EXPECT_EQ(runs.size(), 1u) << data_dir;
  return runs.size() == 1 ? runs[0] : std::filesystem::path();
}

inline msg::RunManifest read_manifest(const std::filesystem::path& run_dir) {
  try {
    return run_folder::read_manifest(run_dir);
  } catch (const std::exception& e) {
    ADD_FAILURE() << e.what();
    return {};
  }
}

}  // namespace plenopiv::testing_support
