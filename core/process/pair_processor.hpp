// The owner of "a pair becomes vectors": camera, calibration and settings built once into an
// operator, then any number of raw frame pairs through it, from any caller.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/base/image.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_model.hpp"
#include "core/process/black_level.hpp"
#include "core/process/operator_cache.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"

namespace plenopiv::process {

class DepthResponse;  // depth_response.hpp

// Raw camera counts as the float image the reconstruction reads.
ImageF to_float(const ImageU16& raw);

// `image` read out in blocks of `factor` x `factor` pixels: the frames of
// optics::CameraModel::binned(factor). Each pixel is the mean of its block, so that counts,
// thresholds and the white correction keep their scale (summed in float: exact for 16-bit counts
// up to 8 x 8). InputError when `factor` is below 1 or does not divide the image's size.
ImageF bin_pixels(const ImageF& image, int factor);
// The same straight from camera counts (no sensor-sized float copy); `factor` 1: to_float.
ImageF bin_pixels(const ImageU16& image, int factor);

// The pulse separation a pair's velocities use: the one the laser's Q-switch sync measured for the
// pair when there is one (> 0), else the nominal dt_s of the settings.
double pair_dt_s(const ProcessSettings& settings, std::optional<double> measured_dt_s);

// The buffers of one pair in flight: MART's (recon::MartWorkspace, about half a gigabyte at the
// paper's scale; frame B reuses frame A's) and the correlation's (four volumes).
struct PairWorkspace {
  recon::MartWorkspace mart;
  piv::CorrelationWorkspace correlation;
};

// Pair workspaces kept from pair to pair: a pair takes a free one, or a new one when all are in
// use, and gives it back when done (also when processing throws). As many exist as pairs were ever
// in flight at once. Thread safe. Not per thread: a TBB thread waiting inside one pair's
// reconstruction may run another pair.
class WorkspacePool {
 public:
  class Lease {
   public:
    Lease(WorkspacePool& pool, std::unique_ptr<PairWorkspace> workspace);
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    ~Lease();
    PairWorkspace& operator*() const { return *workspace_; }

   private:
    WorkspacePool& pool_;
    std::unique_ptr<PairWorkspace> workspace_;
  };
  Lease take();
  // Makes at least `count` workspaces free and passes each free one to `prepare` (the daemon sizes
  // them before a run's first pair). Holds the pool meanwhile: take() waits.
  void reserve(int count, const std::function<void(PairWorkspace&)>& prepare);
  std::size_t bytes();  // held by the free workspaces (their buffers' capacities)

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<PairWorkspace>> free_;
};

// The PairProgress stage of a depth response a PairProcessor measures with its first pair
// (ProcessorSetup::defer_depth_response), its fraction that of the response.
inline constexpr std::string_view kDeferredDepthResponseStage = "depth response";

// What one call needs besides the frames.
struct PairOptions {
  std::optional<double> measured_dt_s;  // this pair's measured pulse separation, if measured
  PairProgress progress;                // also where a caller cancels (throw plenopiv::Cancelled)
};

// How a PairProcessor is set up besides its camera, calibration and settings; every part optional.
struct ProcessorSetup {
  // Where the operator comes from when it was built before from the same camera, calibration,
  // volume and sampling (kept in memory, or its tables on disk), and where a new one is kept; null:
  // the operator is built. Outlives the constructor. The results are the same bits either way.
  OperatorCache* operators = nullptr;
  // The fraction of the depth response's measurement done, after each of its pairs and within them
  // (measure_depth_response); a caller ends the set-up there by throwing (plenopiv::Cancelled), and
  // nothing is kept.
  std::function<void(double)> progress;
  // Where the depth response is read from when it was measured before with the same inputs,
  // settings and executable, and kept when measured (DepthResponseDiskCache); empty: the disk
  // folder of `operators`, if any.
  std::filesystem::path response_folder;
  // The depth response measured by the first process() call instead of the constructor, with that
  // call's PairOptions::progress (stage "depth response") in place of `progress`: plenopivd's
  // quality lane, whose run acquires meanwhile.
  bool defer_depth_response = false;
};

// Built once per camera, calibration and settings (the weight tables: seconds at paper scale),
// then used by any number of pairs, concurrently. Every caller (plenopivd's live lanes, `plenopiv
// process`, `process --run`, the benchmarks, cluster jobs) goes through it, so that where their
// settings agree their results agree bit for bit.
class PairProcessor {
 public:
  // InputError when the settings and camera do not fit (the volume behind the main lens's focal
  // length, windows larger than the volume, a pixel binning that does not divide the sensor, ...).
  // With settings.depth_response_ppm above 0 the depth response is measured (minutes at the
  // paper's scale) or read back (ProcessorSetup), here or, deferred, by the first process() call.
  PairProcessor(const optics::CameraModel& camera, const calib::LoadedCalibration& calibration,
                ProcessSettings settings, const ProcessorSetup& setup = {});
  ~PairProcessor();

  // Raw frames A and B (the camera's counts) to vectors: validated (sensor-sized; named "frame A"
  // and "frame B"), each frame's black level taken off (settings.black_level; the counts in
  // PairResult::black_level_a and _b), resampled when the operator says so, reconstructed and correlated
  // (process_pair), with the dt pair_dt_s gives. With settings.pixel_binning above 1 the operator
  // is built on the binned camera and white image, and frames are validated raw, then binned.
  // MART's and the correlation's buffers come from the processor's pool.
  // With settings.depth_response_ppm above 0, w (and its uncertainty) is then taken through the
  // depth response, and every sigma widened by the error its pairs showed beyond the correlation's
  // sigma (depth_response.hpp). A deferred response is taken by the first call, concurrent calls
  // waiting for it; where that call is given up (its progress threw), the next one takes it; where
  // the settings cannot have one (InputError naming the layer), that and every later call throw it.
  PairResult process(const ImageU16& frame_a, const ImageU16& frame_b, const PairOptions& options = {}) const;
  PairResult process(const ImageF& frame_a, const ImageF& frame_b, const PairOptions& options = {}) const;
  // process() without the depth response's correction: what the response is measured with.
  PairResult process_uncorrected(const ImageU16& frame_a, const ImageU16& frame_b,
                                 const PairOptions& options = {}) const;

  const ProcessSettings& settings() const { return settings_; }
  const PairOperator& op() const { return *op_; }
  // Why and how frames are resampled (PairOperator::note), empty when they are not.
  const std::string& note() const { return op_->note(); }
  // How each frame's black level is found (BlackLevelMeter::describe), or that none is taken off.
  const std::string& black_level_note() const { return black_level_note_; }
  // Where the weight tables came from, for the user: "operator built", "operator kept in memory",
  // or the disk cache's line (WeightsDiskCache::last_note); then, with a depth response, where it
  // came from and its summary (deferred: "depth response deferred to the first pair").
  const std::string& setup_note() const { return setup_note_; }
  // Whether what the setup made or read (the weight tables; the depth response, where the settings
  // ask for one, unless deferred) is in the disk folder of `operators`, for a later processor with
  // the same inputs to read: false without such a folder, or where it could not keep something.
  bool setup_on_disk() const { return setup_on_disk_; }
  // The depth response process() corrects w with; null when settings.depth_response_ppm is 0, and
  // a deferred one until a process() call of this thread has returned.
  const DepthResponse* depth_response() const { return depth_response_.get(); }
  // Where the depth response came from (the cache's line) and its summary; empty when there is
  // none yet (as depth_response()).
  const std::string& depth_response_note() const { return response_note_; }
  // Makes the pool hold `pairs` workspaces sized for this operator's largest reconstruction and
  // correlation (recon::MartWorkspace::reserve, piv::CorrelationWorkspace::reserve), so that up to
  // `pairs` pairs in flight at once allocate and page-fault none of them. plenopivd calls it while
  // a run is Armed: a lane's first pair then takes no gigabytes of fresh memory beside the
  // recording. Seconds at the paper's scale; changes no result. Returns the bytes the pool's
  // workspaces hold.
  std::size_t reserve_workspaces(int pairs) const;

 private:
  // process_pair on frames already in the operator's pixels, in a workspace from the pool; the
  // black levels taken off them are recorded in the result.
  PairResult run(const ImageF& frame_a, const ImageF& frame_b, const PairOptions& options,
                 std::array<BlackLevels, 2> black_levels) const;
  // A raw frame (validated) in the operator's pixels with its black level off: binned, the level
  // subtracted; `frame` itself when neither changes it (no copy).
  template <typename Frame>
  const ImageF& prepared(const Frame& frame, const BlackLevels& levels, ImageF& scratch) const;
  PairResult process_uncorrected(const ImageF& frame_a, const ImageF& frame_b, const PairOptions& options) const;
  // w through depth_response_, when there is one; sigma_method says what sigma holds either way.
  PairResult corrected(PairResult result) const;
  // Measures the depth response, or reads it back, into depth_response_ and response_note_.
  void take_depth_response(const std::function<void(double)>& progress) const;
  // A deferred depth response taken once, by the first caller; the others wait.
  void take_deferred_depth_response(const PairProgress& progress) const;

  ProcessSettings settings_;
  int raw_width_ = 0, raw_height_ = 0;  // the camera's sensor, before pixel binning
  BlackLevelMeter black_level_;         // on the raw sensor; no samples with BlackLevel::none
  std::string black_level_note_;
  std::shared_ptr<const PairOperator> op_;
  std::string setup_note_;
  bool setup_on_disk_ = false;
  // What a depth response is measured from (settings.depth_response_ppm above 0), and where it is
  // kept; deferred: taken by the first process() call.
  struct ResponseSource;
  std::unique_ptr<const ResponseSource> response_source_;
  bool response_deferred_ = false;
  mutable std::once_flag response_once_;
  mutable std::unique_ptr<const DepthResponse> depth_response_;
  mutable std::string response_note_;
  mutable bool response_kept_ = false;    // the response is in the folder (read from it, or written)
  mutable std::string response_refused_;  // why a deferred response could not be had; empty: it could
  mutable WorkspacePool workspaces_;
};

}  // namespace plenopiv::process
