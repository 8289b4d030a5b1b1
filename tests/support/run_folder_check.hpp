// Tests: a run folder left by plenopivd checked as a user meets it: consistent, and reprocessable.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "core/base/errors.hpp"
#include "core/io/hdf5_files.hpp"
#include "proto/run_folder.hpp"
#include "tests/support/child_process.hpp"

namespace plenopiv::testing_support {

// The manifest parses; every listed frame is a whole TIFF of width_px x height_px; every listed
// vector field reads; `plenopiv process --run` reprocesses the folder into re-<run> beside it, or,
// for a run with no pair, refuses it by name. Test failures name what is wrong. The manifest.
inline msg::RunManifest expect_consistent_and_reprocessable(const std::filesystem::path& run, int width_px,
                                                            int height_px) {
  SCOPED_TRACE(run.string());
  msg::RunManifest manifest;
  std::ifstream in(run / "manifest.json");
  const std::string text{std::istreambuf_iterator<char>(in), {}};
  try {
    manifest = run_folder::parse_manifest(text, run.string());
  } catch (const InputError& e) {
    ADD_FAILURE() << "manifest: " << e.what() << "\n" << text;
    return manifest;
  }
  std::string out;
  const int status = run_command({binary("plenopiv"), "process", "--run", run.string(), "-o",
                                  (run.parent_path() / ("re-" + run.filename().string())).string()},
                                 out, std::chrono::seconds(300));
  if (manifest.pairs_size() == 0) {
    EXPECT_EQ(status, 2) << out;
    EXPECT_NE(out.find("the run recorded no pair"), std::string::npos) << out;
    return manifest;
  }
  try {
    const run_folder::Reader reader(run);
    reader.check_frames(width_px, height_px);
    for (const run_folder::PairEntry& p : reader.pairs()) {
      if (!p.vectors.empty()) {
        EXPECT_NO_THROW(io::read_vector_field_h5(run / p.vectors)) << p.vectors;
      }
    }
  } catch (const InputError& e) {
    ADD_FAILURE() << "inconsistent run folder: " << e.what();
  }
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("process: 100%"), std::string::npos) << out;
  return manifest;
}

}  // namespace plenopiv::testing_support
