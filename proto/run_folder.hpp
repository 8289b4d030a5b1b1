// The run folder: written by plenopivd as a run goes, read by `plenopiv process --run` and the
// cluster jobs; the one library that knows its layout and its manifest.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/piv/statistics.hpp"
#include "core/process/process.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::run_folder {

// run-<id>/:
//   run.yaml                 the run config as sent
//   process.yaml             its processing keys (core/process schema): what reprocessing reads
//   camera.yaml              the daemon's camera file, if it has one
//   calibration.h5           the calibration file the run processed with, byte for byte, if any
//   frames/pair-<n>-A.tif    raw frames, 16-bit TIFF, every pair the camera delivered
//   frames/pair-<n>-B.tif
//   vectors/pair-<n>.h5      vector fields made with the full settings (either lane)
//   vectors/live/pair-<n>.h5 vector fields made with the live tier (the live lane, when the run has one)
//   statistics.h5            mean velocity (u, v, w) and u_rms, v_rms, w_rms, count per node (full settings)
//   statistics-live.h5       the same over the live tier's fields
//   manifest.json            msg::RunManifest as JSON (64-bit integers as JSON numbers)
//   journal.jsonl            while recording: one msg::ManifestJournalEntry per line, each pair,
//                            field, drop and warning since manifest.json was written
// Every file is written under a temporary name, fsynced and renamed. manifest.json is written at
// the start and, with everything, at the end (then the journal is removed); in between each pair
// and field is appended to the journal once its files are on disk (one line, fdatasync), so the
// cost of recording a pair does not grow with the run, and whatever stops the writer, manifest
// plus journal (read_manifest) list exactly the complete files.

// The manifest as JSON: protobuf's JSON mapping, but with 64-bit integers as numbers (protobuf
// writes them as strings; its parser takes either).
std::string manifest_json(const msg::RunManifest& manifest);
// Parses manifest.json text; InputError naming `source` when it is not a run manifest.
msg::RunManifest parse_manifest(const std::string& json, const std::string& source);
// A run folder's manifest as it stands: manifest.json with its journal (if any) applied. A journal
// line cut short by a crash (the last, without its newline) lists nothing and is ignored; any other
// line that does not parse is an InputError naming the file and line.
msg::RunManifest read_manifest(const std::filesystem::path& run_dir);

// One recorded pair as the writer stores it (what a camera delivered, and the laser pulses the
// trigger measured for it).
struct PairRecord {
  std::uint64_t pair_index = 0, trigger_index = 0;
  const ImageU16* frame_a = nullptr;
  const ImageU16* frame_b = nullptr;
  std::uint64_t frame_id_a = 0, frame_id_b = 0;
  std::uint64_t device_timestamp_a_ns = 0, device_timestamp_b_ns = 0;
  std::uint64_t host_timestamp_a_ns = 0, host_timestamp_b_ns = 0;
  double frame_gap_s = 0;  // B - A, device clock when both frames carry it, else host
  std::optional<std::pair<std::uint64_t, std::uint64_t>> laser_pulses_ns;  // measured pulse 1 and 2
  // If set, see each frame's rows as they are written (io::write_tiff's visitor); A's and B's are
  // called from different threads at once.
  std::function<void(std::span<const std::uint16_t>)> visit_rows_a, visit_rows_b;
};

// A calibration file copied into the folder.
struct CalibrationCopy {
  std::filesystem::path source;  // where it was read
  std::string bytes;             // what was read (and processed with)
  std::uint32_t crc32 = 0;
};

// What a manifest's journal is applied with: where each pair is, which triggers have a recorded
// pair and which are listed dropped.
struct ManifestIndex {
  std::unordered_map<std::uint64_t, int> pair_position;  // pair_index -> its place in manifest.pairs
  std::unordered_set<std::uint64_t> recorded_triggers, dropped_triggers;
};

// Writes a run folder as a run goes. Thread safe: frames, vectors and close may come from
// different threads.
class Writer {
 public:
  struct Setup {
    std::filesystem::path data_dir;
    std::string run_id;
    std::string run_yaml;      // the run config as sent
    std::string process_yaml;  // its processing keys (RunConfig::process_yaml)
    double nominal_dt_s = 0, rate_hz = 0;
    std::string camera_uri, trigger_uri;
    std::filesystem::path camera_file;  // copied as camera.yaml; empty: none
    std::string camera_model;
    std::string camera_triggering;               // drivers::CameraWiring::description
    std::optional<CalibrationCopy> calibration;  // none: the camera's nominal lattice
  };
  // Creates the folder (InputError if it exists or cannot be made) and the first manifest.
  explicit Writer(const Setup& setup);
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  const std::filesystem::path& dir() const { return dir_; }
  // Writes both frames (together, each fsynced) and lists the pair. Throws if the disk refuses.
  void record_pair(const PairRecord& pair);
  // Writes the pair's vector field made with `tier`'s settings (process::write_vector_field_files:
  // vorticity, `flags` when given, provenance with the tier), lists it (ManifestPair vectors or
  // live_vectors), and adds it to that tier's running statistics. A pair may have one field of each
  // tier; neither overwrites the other.
  void record_vectors(std::uint64_t pair_index, const VectorField& field, std::span<const std::uint8_t> flags = {},
                      process::Tier tier = process::Tier::full);
  // Lists pairs the camera dropped, with the reason, in the manifest (the first kMaxListedDrops;
  // the losses count them all).
  void record_drop(std::uint64_t trigger_index, const std::string& reason);
  static constexpr int kMaxListedDrops = 10000;
  // Bad data met on the way (all-zero or saturated frames, ...): listed once each.
  void add_warning(const std::string& warning);
  // Writes the final manifest with `state` ("complete", "stopped", "failed: ..."), the losses, the
  // raw frames lost and the lanes' counters, then statistics (of each tier that recorded a field),
  // and removes the journal. Later calls do nothing.
  void close(const std::string& state, std::uint64_t processed, std::uint64_t skipped, const msg::Losses& losses = {},
             std::uint64_t frames_lost = 0, const std::vector<msg::LaneCounters>& lanes = {});

  std::uint64_t pairs_recorded() const;
  msg::RunManifest manifest() const;

 private:
  void write_manifest_locked();
  void write_statistics_locked();
  // Appends one entry to the journal; with `sync`, waits for the disk (fdatasync) to hold it and
  // every line before it.
  void journal_locked(const msg::ManifestJournalEntry& entry, bool sync = true);

  mutable std::mutex mutex_;
  std::filesystem::path dir_;
  msg::RunManifest manifest_;
  ManifestIndex index_;
  int journal_fd_ = -1;
  std::string process_yaml_;                             // the run's processing keys, each vector file's provenance
  piv::RunningStatistics statistics_, live_statistics_;  // over the full and the live tier's fields
  double nominal_dt_s_ = 0;
  bool closed_ = false;
};

// A pair as a reader sees it: its frames (checked to lie inside the folder), its measured dt.
struct PairEntry {
  std::uint64_t pair_index = 0, trigger_index = 0;
  std::filesystem::path frame_a, frame_b;  // absolute
  std::optional<double> measured_dt_s;     // the laser's pulse separation for this pair, if measured
  std::string vectors;                     // the run's field with the full settings (relative), empty if none
  std::string live_vectors;                // the run's field with the live tier (relative), empty if none
};

// Reads a run folder from the folder alone, checking everything before anything is processed: the
// manifest parses; process.yaml and camera.yaml exist; the calibration is nominal, or the folder's
// calibration.h5 with the size and CRC-32 the manifest recorded; every file the manifest names
// (settings, camera, calibration, frames) lies inside the folder and exists; every frame is listed
// once. InputError naming the manifest key and file otherwise.
class Reader {
 public:
  explicit Reader(const std::filesystem::path& dir);

  const std::filesystem::path& dir() const { return dir_; }
  const msg::RunManifest& manifest() const { return manifest_; }
  std::filesystem::path process_file() const;
  std::filesystem::path camera_file() const;
  // The folder's calibration.h5, or nullopt when the run used the camera's nominal lattice.
  const std::optional<std::filesystem::path>& calibration_file() const { return calibration_; }
  const std::vector<PairEntry>& pairs() const { return pairs_; }
  // Checks every frame's TIFF header (a whole file of `width` x `height` px): a truncated frame is
  // found before the first pair is processed.
  void check_frames(int width, int height) const;

 private:
  std::filesystem::path file(const std::string& key, const std::string& name) const;

  std::filesystem::path dir_;
  msg::RunManifest manifest_;
  std::optional<std::filesystem::path> calibration_;
  std::vector<PairEntry> pairs_;
};

// Marks every run folder under `data_dir` whose manifest still says "recording" (its daemon ended
// without closing it: a crash, SIGKILL, power cut) as "interrupted", with the time it was found;
// its files stay as the manifest lists them. Returns the folders marked. Folders that cannot be
// read are skipped and named in `problems`.
std::vector<std::filesystem::path> mark_interrupted_runs(const std::filesystem::path& data_dir,
                                                         std::vector<std::string>* problems = nullptr);

// statistics.h5: a vector field holding the mean velocity (over the nominal dt: u, v, w read back
// as the mean, in m/s), beside it u_rms, v_rms, w_rms (m/s), count (valid samples per node) and
// valid_fraction (count / fields); the attribute `fields` says how many fields went in (paper
// sec 7). One writer for the live run's and the reprocessed run's statistics.
void write_statistics(const std::filesystem::path& path, const piv::RunningStatistics& statistics, double nominal_dt_s,
                      std::uint64_t fields);

// A file name-safe run id from the current UTC time: 20261123-035512.
std::string new_run_id();
// What a run folder's name starts with, before its run id.
inline constexpr std::string_view kRunFolderPrefix = "run-";
// The folder a run of this id has under `data_dir`: <data_dir>/run-<id>.
std::filesystem::path run_dir(const std::filesystem::path& data_dir, const std::string& run_id);
// "pair-000042": the stem of a pair's files.
std::string pair_name(std::uint64_t pair_index);

}  // namespace plenopiv::run_folder
