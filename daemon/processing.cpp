// The live processing stage: raw pair → process::process_pair (MART of A and B, 3D correlation).
#include "daemon/processing.hpp"

#include <spdlog/spdlog.h>

#include <memory>
#include <mutex>
#include <vector>

#include "core/base/errors.hpp"
#include "core/base/memory.hpp"
#include "core/base/yaml_access.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::daemon {
namespace {

ImageF to_float(const ImageU16& image) {
  ImageF out(image.width, image.height);
  for (std::size_t i = 0; i < image.size(); ++i) out.pixels[i] = float(image.pixels[i]);
  return out;
}

// MART's buffers (recon::MartWorkspace, ~0.6 GB each on the paper case) kept from pair to pair of
// a run: a pair takes a free one (or a new one when all are in use, so there are as many as pairs
// were ever in flight at once) and gives it back when done, also when processing fails. Not per
// thread: a TBB thread waiting inside one pair's reconstruction may run another pair's.
class WorkspacePool {
 public:
  class Lease {
   public:
    Lease(WorkspacePool& pool, std::unique_ptr<recon::MartWorkspace> workspace)
        : pool_(pool), workspace_(std::move(workspace)) {}
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    ~Lease() { pool_.give_back(std::move(workspace_)); }
    recon::MartWorkspace& operator*() const { return *workspace_; }

   private:
    WorkspacePool& pool_;
    std::unique_ptr<recon::MartWorkspace> workspace_;
  };

  Lease take() { return Lease(*this, free_or_new()); }

 private:
  std::unique_ptr<recon::MartWorkspace> free_or_new() {
    std::lock_guard lock(mutex_);
    if (free_.empty()) return std::make_unique<recon::MartWorkspace>();
    std::unique_ptr<recon::MartWorkspace> workspace = std::move(free_.back());
    free_.pop_back();
    return workspace;
  }
  void give_back(std::unique_ptr<recon::MartWorkspace> workspace) {
    std::lock_guard lock(mutex_);
    free_.push_back(std::move(workspace));
  }

  std::mutex mutex_;
  std::vector<std::unique_ptr<recon::MartWorkspace>> free_;
};

}  // namespace

ProcessFactory plenoptic_processing(const optics::CameraModel& camera) {
  return [camera](const RunConfig& config, const RunCalibration& calibration) -> ProcessFn {
    // The run's settings go through the text the run folder keeps (process.yaml), so the live
    // stage and `plenopiv process --run` read exactly the same settings the same way.
    const process::ProcessSettings settings =
        process::process_settings_from(YamlMap(load_yaml_text(config.process_yaml(), "run config"), "run config"));
    // A run's volume is refused before any table is built when the pairs it keeps in flight would not
    // fit this machine: kPeakBytesPerVoxel is the measured peak per reconstructed voxel of one pair
    // (tables, MART buffers, both volumes, correlation; docs/benchmarks.md "Speed and memory").
    constexpr double kPeakBytesPerVoxel = 160;
    const Grid3 g = settings.reconstruction_grid();
    require_memory(double(g.shape[0]) * g.shape[1] * g.shape[2] * kPeakBytesPerVoxel * config.max_pairs_in_flight,
                   "processing " + std::to_string(config.max_pairs_in_flight) + " pair(s) at once on a " +
                       std::to_string(g.shape[0]) + " x " + std::to_string(g.shape[1]) + " x " +
                       std::to_string(g.shape[2]) + " voxel volume (volume, max_pairs_in_flight)");
    // Built once per run, shared read-only by the concurrent pairs. PairOperator resamples the
    // frames onto an axis-aligned lattice when the array is not separable (a calibrated array is
    // always rotated a little; never the nominal lattice): said in the log when it does.
    std::shared_ptr<const process::PairOperator> op;
    if (calibration.loaded) {
      op = std::make_shared<const process::PairOperator>(camera, calibration.loaded->lenses,
                                                         calibration.loaded->white_correction, settings);
    } else {
      const calib::LoadedCalibration nominal = calib::nominal_calibration(camera);
      op = std::make_shared<const process::PairOperator>(camera, nominal.lenses, nominal.white_correction, settings);
    }
    spdlog::info("run processing: calibration {}; {}", calibration.summary(),
                 op->note().empty() ? "frames reconstructed on raw pixels" : op->note());
    const bool keep_volumes = config.publish_volumes;
    auto workspaces = std::make_shared<WorkspacePool>();
    return [op, settings, keep_volumes, workspaces](const drivers::FramePair& pair, const CancelFlag& cancel) {
      process::ProcessSettings s = settings;
      if (pair.measured && pair.measured->dt_s() > 0) s.correlation.dt_s = pair.measured->dt_s();
      const WorkspacePool::Lease workspace = workspaces->take();
      // Called after every MART iteration and correlation pass: a stopping run gives up there.
      const process::PairProgress check_cancel = [&cancel](const std::string&, double) {
        if (cancel) throw Cancelled("run stopping");
      };
      process::PairResult r = process::process_pair(*op, to_float(pair.a.image), to_float(pair.b.image), s,
                                                    check_cancel, &*workspace);
      ProcessedPair out;
      out.vectors = std::move(r.correlation.field);
      if (keep_volumes) {
        out.volume_a = std::move(r.volume_a);
        out.volume_b = std::move(r.volume_b);
      }
      return out;
    };
  };
}

}  // namespace plenopiv::daemon
