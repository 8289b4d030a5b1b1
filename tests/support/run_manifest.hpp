// Tests: a run folder's manifest read back as the RunManifest message, with its journal applied
// (run_folder::read_manifest), a test failure, not an exception, when it does not read.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>

#include "plenopiv.pb.h"
#include "proto/run_folder.hpp"

namespace plenopiv::testing_support {

inline msg::RunManifest read_manifest(const std::filesystem::path& run_dir) {
  try {
    return run_folder::read_manifest(run_dir);
  } catch (const std::exception& e) {
    ADD_FAILURE() << e.what();
    return {};
  }
}

}  // namespace plenopiv::testing_support
