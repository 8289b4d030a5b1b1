// The run folder: raw frames, vector fields, statistics and a manifest that always matches the disk.
#pragma once

#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "core/base/grid.hpp"
#include "daemon/run_calibration.hpp"
#include "daemon/run_config.hpp"
#include "daemon/statistics.hpp"
#include "drivers/camera/camera.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::daemon {

// run-<id>/ under the data directory:
//   run.yaml                 the run config as sent
//   camera.yaml              the daemon's camera file, if it has one
//   calibration.h5           the calibration file the run processed with, byte for byte, if any
//   process.yaml             the processing settings resolved from run.yaml (core/process schema)
//   frames/pair-<n>-A.tif    raw frames, 16-bit TIFF, every pair the camera delivered
//   frames/pair-<n>-B.tif
//   vectors/pair-<n>.h5      vector fields of the pairs the live path processed
//   statistics.h5            mean velocity (u, v, w) and u_rms, v_rms, w_rms, count per node
//   manifest.json            RunManifest as JSON
// Every file is written under a temporary name and renamed; the manifest is rewritten (atomically)
// after each file, so whatever stops the daemon, the manifest lists exactly the complete files.
// The folder alone is enough to reprocess the run (`plenopiv process --run`).
// Thread safe: frames, vectors and close may come from different threads.
class Recorder {
 public:
  struct Setup {
    std::filesystem::path data_dir;
    std::string run_id;
    const RunConfig* config = nullptr;
    std::string camera_uri, trigger_uri;
    std::filesystem::path camera_file;  // empty: none
    std::string camera_model;
    std::string camera_triggering;  // drivers::CameraWiring::description
    // What the processing uses for lens centres and white: null or nominal, the camera's nominal
    // lattice; else its bytes are written to calibration.h5 and the manifest names it with the
    // source path, size and CRC-32.
    const RunCalibration* calibration = nullptr;
  };
  // Creates the folder (InputError if it exists or cannot be made) and the first manifest.
  explicit Recorder(const Setup& setup);

  const std::filesystem::path& dir() const { return dir_; }
  // Writes both frames and lists the pair. Throws if the disk refuses (the run then fails).
  void record_pair(const drivers::FramePair& pair);
  // Writes the pair's vector field, lists it, and adds it to the running statistics.
  void record_vectors(std::uint64_t pair_index, const VectorField& field);
  // Lists pairs the camera dropped, with the reason, in the manifest (the first kMaxListedDrops;
  // the losses count them all). The manifest is rewritten with the next file or at close.
  void record_drops(const std::vector<drivers::PairDrop>& drops);
  static constexpr int kMaxListedDrops = 10000;
  // Bad data met on the way (all-zero or saturated frames, ...): listed once each.
  void add_warning(const std::string& warning);
  // Writes statistics (if any field was recorded) and the final manifest with `state`
  // ("complete", "stopped", "failed: ..."), the losses and the raw frames lost. Later calls do nothing.
  void close(const std::string& state, std::uint64_t processed, std::uint64_t skipped,
             const msg::Losses& losses = {}, std::uint64_t frames_lost = 0);

  std::uint64_t pairs_recorded() const;
  msg::RunManifest manifest() const;

 private:
  void write_manifest_locked();
  void write_statistics_locked();

  mutable std::mutex mutex_;
  std::filesystem::path dir_;
  msg::RunManifest manifest_;
  RunningStatistics statistics_;
  double nominal_dt_s_ = 0;
  bool closed_ = false;
};

// Marks every run folder under `data_dir` whose manifest still says "recording" (its daemon ended
// without closing it: a crash, SIGKILL, power cut) as "interrupted", with the time it was found;
// its files stay as the manifest lists them. Returns the folders marked. Folders that cannot be
// read are skipped and named in `problems`.
std::vector<std::filesystem::path> mark_interrupted_runs(const std::filesystem::path& data_dir,
                                                         std::vector<std::string>* problems = nullptr);

// A file name-safe run id from the current UTC time: 20261123-035512.
std::string new_run_id();
// Time between the two frames of a pair: B - A on the device clock when both frames carry it,
// else on the host clock. (Not the laser's dt: frame B starts after the interline transfer.)
double frame_gap_s(const drivers::FramePair& pair);

}  // namespace plenopiv::daemon
