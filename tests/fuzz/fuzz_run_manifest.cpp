// Fuzz target: a run folder's manifest.json and journal.jsonl as their readers meet them
// (proto/run_folder): parse_manifest, read_manifest, the Reader that `plenopiv process --run` opens
// a folder with, and the daemon's mark_interrupted_runs at start. The input is the manifest, then,
// after a line "#journal", the journal (none without it). The folder holds the seed run's other
// files (process.yaml, camera.yaml, calibration.h5, two frames), so a manifest that names them is
// read through. Properties: a manifest (with its journal) is read or refused naming the folder's
// file; every path a Reader hands out lies inside the folder; a folder left "recording" is marked
// "interrupted" with its pairs and the journal's kept and the journal folded in; any other manifest
// is left byte for byte; a journal is never left beside a manifest the daemon has seen.
#include <fstream>
#include <iterator>

#include "proto/run_folder.hpp"
#include "tests/fuzz/seed_camera.hpp"

using namespace plenopiv;
namespace fs = std::filesystem;

namespace {

std::string read(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// True when `path` is `dir` or below it, as text (no symbolic links in the scratch folder).
bool inside(const fs::path& path, const fs::path& dir) {
  const fs::path rel = path.lexically_normal().lexically_relative(dir.lexically_normal());
  return !rel.empty() && *rel.begin() != "..";
}

// The files beside the manifest, written once: small stand-ins with the seed run's names.
void write_folder(const fs::path& run) {
  fs::create_directories(run / "frames");
  fs::create_directories(run / "vectors");
  for (const char* name : {"process.yaml", "run.yaml", "calibration.h5", "frames/pair-000000-A.tif",
                           "frames/pair-000000-B.tif", "vectors/pair-000000.h5"}) {
    std::ofstream(run / name) << name;
  }
  fs::copy_file(fuzzing::seed_camera_file(), run / "camera.yaml", fs::copy_options::overwrite_existing);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string input = fuzzing::as_text(data, size);
  const fs::path data_dir = fuzzing::scratch_dir() / "data";
  const fs::path run = data_dir / "run-20260101-000000";
  static const bool written = (write_folder(run), true);
  (void)written;
  const std::string mark = "\n#journal\n";
  const std::size_t cut = input.find(mark);
  const std::string text = input.substr(0, cut);
  const fs::path manifest = run / "manifest.json", journal = run / "journal.jsonl";
  std::ofstream(manifest, std::ios::binary | std::ios::trunc) << text;
  fs::remove(journal);
  if (cut != std::string::npos) std::ofstream(journal, std::ios::binary) << input.substr(cut + mark.size());

  std::optional<msg::RunManifest> before;
  try {
    before = run_folder::parse_manifest(text, manifest.string());
  } catch (const InputError& e) {
    fuzzing::require_names(e, manifest.string());
  }
  std::optional<msg::RunManifest> merged;
  try {
    merged = run_folder::read_manifest(run);
    fuzzing::require(before.has_value(), "read_manifest read a manifest parse_manifest refuses");
  } catch (const InputError& e) {
    fuzzing::require_names(e, run.string());
  }

  try {
    const run_folder::Reader reader(run);
    fuzzing::require(merged.has_value(), "a Reader opened a folder whose manifest does not read");
    fuzzing::require(!reader.pairs().empty(), "a Reader opened a folder without pairs");
    fuzzing::require(
        inside(reader.process_file(), run) && inside(reader.camera_file(), run),
        "a Reader points outside its folder: " + reader.process_file().string() + ", " + reader.camera_file().string());
    if (reader.calibration_file()) {
      fuzzing::require(inside(*reader.calibration_file(), run), "a Reader's calibration lies outside its folder");
    }
    for (const run_folder::PairEntry& p : reader.pairs()) {
      fuzzing::require(inside(p.frame_a, run) && inside(p.frame_b, run),
                       "a Reader's frame lies outside its folder: " + p.frame_a.string() + ", " + p.frame_b.string());
    }
  } catch (const InputError& e) {
    fuzzing::require_names(e, run.string());
  }

  std::vector<std::string> problems;
  const std::vector<fs::path> marked = run_folder::mark_interrupted_runs(data_dir, &problems);
  if (!before) {
    fuzzing::require(marked.empty() && problems.size() == 1 && problems[0].find(run.string()) != std::string::npos,
                     "a manifest that does not parse was not named as a problem");
    fuzzing::require(read(manifest) == text, "a manifest that does not parse was changed");
    return 0;
  }
  if (!merged) {
    fuzzing::require(marked.empty() && problems.size() == 1 && problems[0].find(run.string()) != std::string::npos,
                     "a journal that does not read was not named as a problem");
    fuzzing::require(read(manifest) == text, "a manifest whose journal does not read was changed");
    return 0;
  }
  fuzzing::require(problems.empty(),
                   "a manifest that reads was named as a problem: " + (problems.empty() ? std::string() : problems[0]));
  fuzzing::require(!fs::exists(journal), "a journal was left beside a manifest the daemon has seen");
  if (before->state() != "recording") {
    fuzzing::require(marked.empty() && read(manifest) == text, "a closed run's manifest was changed");
    return 0;
  }
  fuzzing::require(marked.size() == 1 && marked[0] == run, "a run left recording was not marked");
  msg::RunManifest after;
  try {
    after = run_folder::parse_manifest(read(manifest), manifest.string());
  } catch (const InputError& e) {
    fuzzing::broken(std::string("a marked manifest does not parse: ") + e.what());
  }
  fuzzing::require(after.state() == "interrupted" && after.pairs_size() == merged->pairs_size() &&
                       after.run_id() == before->run_id(),
                   "a marked manifest lost its pairs or was not marked interrupted");
  return 0;
}
