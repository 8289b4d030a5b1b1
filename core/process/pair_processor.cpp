// The owner of "a pair becomes vectors": camera, calibration and settings built once into an
// operator, then any number of raw frame pairs through it, from any caller.
#include "core/process/pair_processor.hpp"

namespace plenopiv::process {

ImageF to_float(const ImageU16& raw) {
  ImageF image(raw.width, raw.height);
  for (std::size_t i = 0; i < raw.size(); ++i) image.pixels[i] = float(raw.pixels[i]);
  return image;
}

double pair_dt_s(const ProcessSettings& settings, std::optional<double> measured_dt_s) {
  return measured_dt_s && *measured_dt_s > 0 ? *measured_dt_s : settings.correlation.dt_s;
}

WorkspacePool::Lease::Lease(WorkspacePool& pool, std::unique_ptr<PairWorkspace> workspace)
    : pool_(pool), workspace_(std::move(workspace)) {}

WorkspacePool::Lease::~Lease() {
  std::lock_guard lock(pool_.mutex_);
  pool_.free_.push_back(std::move(workspace_));
}

WorkspacePool::Lease WorkspacePool::take() {
  std::lock_guard lock(mutex_);
  if (free_.empty()) return Lease(*this, std::make_unique<PairWorkspace>());
  std::unique_ptr<PairWorkspace> workspace = std::move(free_.back());
  free_.pop_back();
  return Lease(*this, std::move(workspace));
}

PairProcessor::PairProcessor(const optics::CameraModel& camera, const calib::LoadedCalibration& calibration,
                             ProcessSettings settings, OperatorCache* operators)
    : settings_(std::move(settings)) {
  const optics::CameraModel framed = calib::camera_in_frame(camera, calibration);
  if (operators) {
    op_ = operators->get(framed, calibration.lenses, calibration.white_correction, settings_, &setup_note_);
  } else {
    op_ = std::make_shared<const PairOperator>(framed, calibration.lenses, calibration.white_correction, settings_);
    setup_note_ = "operator built";
  }
}

PairResult PairProcessor::process(const ImageU16& frame_a, const ImageU16& frame_b, const PairOptions& options) const {
  return process(to_float(frame_a), to_float(frame_b), options);
}

PairResult PairProcessor::process(const ImageF& frame_a, const ImageF& frame_b, const PairOptions& options) const {
  ProcessSettings s = settings_;
  s.correlation.dt_s = pair_dt_s(settings_, options.measured_dt_s);
  const WorkspacePool::Lease workspace = workspaces_.take();
  return process_pair(*op_, frame_a, frame_b, s, options.progress, &(*workspace).mart, &(*workspace).correlation);
}

}  // namespace plenopiv::process
