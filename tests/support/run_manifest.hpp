// Tests: a run folder's manifest.json read back as the RunManifest message (a test failure, not an
// exception, when it does not parse).
#pragma once

#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "plenopiv.pb.h"

namespace plenopiv::testing_support {

inline msg::RunManifest read_manifest(const std::filesystem::path& run_dir) {
  std::ifstream in(run_dir / "manifest.json");
  std::stringstream text;
  text << in.rdbuf();
  msg::RunManifest m;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(text.str(), &m).ok()) << text.str();
  return m;
}

}  // namespace plenopiv::testing_support
