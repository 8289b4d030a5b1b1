// The owner of "a pair becomes vectors": camera, calibration and settings built once into an
// operator, then any number of raw frame pairs through it, from any caller.
#include "core/process/pair_processor.hpp"

#include <algorithm>
#include <array>
#include <type_traits>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/base/errors.hpp"
#include "core/process/depth_response.hpp"

namespace plenopiv::process {

ImageF to_float(const ImageU16& raw) {
  ImageF image;
  image.width = raw.width;
  image.height = raw.height;
  image.pixels.assign(raw.pixels.begin(), raw.pixels.end());  // converted in one pass, not zeroed first
  return image;
}

namespace {

// Block means, summed in float: exact for 16-bit counts up to 8 x 8 blocks (64 x 65535 < 2^24).
template <typename T>
ImageF block_means(const Image<T>& image, int factor) {
  if (factor < 1 || image.width % factor != 0 || image.height % factor != 0) {
    throw InputError("pixel binning " + std::to_string(factor) + " does not divide the image's " +
                     std::to_string(image.width) + " x " + std::to_string(image.height) + " px");
  }
  ImageF out;
  out.width = image.width / factor;
  out.height = image.height / factor;
  out.pixels.resize(std::size_t(out.width) * std::size_t(out.height));
  const float scale = 1.0f / float(factor * factor);
  // Output rows are independent (each sums its own block of input rows in a fixed order), so the
  // threads change no bit.
  tbb::parallel_for(tbb::blocked_range<int>(0, out.height, 16), [&](const tbb::blocked_range<int>& rows) {
    std::vector<float> sums(std::size_t(out.width));
    for (int y = rows.begin(); y != rows.end(); ++y) {
      std::fill(sums.begin(), sums.end(), 0.f);
      for (int r = 0; r < factor; ++r) {
        const T* in = image.pixels.data() + std::size_t(y * factor + r) * std::size_t(image.width);
        for (int x = 0; x < out.width; ++x)
          for (int c = 0; c < factor; ++c) sums[std::size_t(x)] += float(in[x * factor + c]);
      }
      float* row = out.pixels.data() + std::size_t(y) * std::size_t(out.width);
      for (int x = 0; x < out.width; ++x) row[x] = sums[std::size_t(x)] * scale;
    }
  });
  return out;
}

}  // namespace

ImageF bin_pixels(const ImageF& image, int factor) {
  if (factor == 1 || image.pixels.empty()) return image;
  return block_means(image, factor);
}

ImageF bin_pixels(const ImageU16& image, int factor) {
  if (factor == 1) return to_float(image);
  return block_means(image, factor);
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

void WorkspacePool::reserve(int count, const std::function<void(PairWorkspace&)>& prepare) {
  std::lock_guard lock(mutex_);
  while (int(free_.size()) < count) free_.push_back(std::make_unique<PairWorkspace>());
  for (const std::unique_ptr<PairWorkspace>& workspace : free_) prepare(*workspace);
}

std::size_t WorkspacePool::bytes() {
  std::lock_guard lock(mutex_);
  std::size_t total = 0;
  for (const std::unique_ptr<PairWorkspace>& workspace : free_)
    total += workspace->mart.bytes() + workspace->correlation.bytes();
  return total;
}

struct PairProcessor::ResponseSource {
  optics::CameraModel camera;  // the simulated pairs are rendered on it, with `lenses`
  optics::MicrolensArray lenses;
  std::filesystem::path folder;  // where it is kept (empty: nowhere)
  std::string key;               // depth_response_key; empty: not kept
};

PairProcessor::~PairProcessor() = default;

PairProcessor::PairProcessor(const optics::CameraModel& camera, const calib::LoadedCalibration& calibration,
                             ProcessSettings settings, const ProcessorSetup& setup)
    : settings_(std::move(settings)), raw_width_(camera.sensor().width_px), raw_height_(camera.sensor().height_px) {
  if (settings_.black_level == BlackLevel::between_images) {
    recon::validate_size(calibration.white_correction.width, calibration.white_correction.height, raw_width_,
                         raw_height_, "the calibration's white correction");
    black_level_ = BlackLevelMeter(calibration.white_correction);
    black_level_note_ = black_level_.describe();
  } else {
    black_level_note_ = "black level: none taken off (reconstruction.black_level: none)";
  }
  OperatorCache* const operators = setup.operators;
  const int binning = settings_.pixel_binning;
  const auto in_binning = [&](auto&& make) {
    try {
      return make();
    } catch (const InputError& e) {
      throw InputError(std::string("reconstruction.pixel_binning: ") + e.what());
    }
  };
  // The lenses stay as calibrated: their centres are in mm about the optical axis, which binning
  // keeps where it is.
  const optics::CameraModel in_frame = calib::camera_in_frame(camera, calibration);
  const optics::CameraModel framed = in_binning([&] { return in_frame.binned(binning); });
  const ImageF binned_white =
      binning == 1 ? ImageF{} : in_binning([&] { return bin_pixels(calibration.white_correction, binning); });
  const ImageF& white = binning == 1 ? calibration.white_correction : binned_white;
  OperatorCache::Provenance provenance;
  if (operators) {
    op_ = operators->get(framed, calibration.lenses, white, settings_, &provenance);
    setup_note_ = provenance.note;
    setup_on_disk_ = provenance.on_disk;
  } else {
    op_ = std::make_shared<const PairOperator>(framed, calibration.lenses, white, settings_);
    setup_note_ = "operator built";
  }
  if (settings_.depth_response_ppm > 0) {
    auto source = std::make_unique<ResponseSource>(ResponseSource{camera, calibration.lenses, {}, {}});
    source->folder = !setup.response_folder.empty() ? setup.response_folder
                     : operators                    ? operators->disk_folder()
                                                    : std::filesystem::path();
    const std::string operator_inputs = operators
                                            ? provenance.key
                                            : operator_key(framed, calibration.lenses, white,
                                                           settings_.reconstruction_grid(), settings_.angular_sampling);
    if (!source->folder.empty()) source->key = depth_response_key(operator_inputs, camera, settings_);
    response_source_ = std::move(source);
    response_deferred_ = setup.defer_depth_response;
    if (response_deferred_) {
      setup_note_ += "; depth response deferred to the first pair";
    } else {
      take_depth_response(setup.progress);
      setup_note_ += "; " + response_note_;
      setup_on_disk_ = setup_on_disk_ && response_kept_;
    }
  }
}

void PairProcessor::take_depth_response(const std::function<void(double)>& progress) const {
  const ResponseSource& source = *response_source_;
  const auto measure = [&] {
    return measure_depth_response(*this, source.camera, source.lenses, settings_.depth_response_ppm, progress);
  };
  std::string note;
  if (!source.key.empty()) {
    DepthResponseDiskCache cache(source.folder);
    depth_response_ = std::make_unique<const DepthResponse>(cache.response(source.key, measure));
    note = cache.last_note();
    response_kept_ = cache.last_outcome() != CacheOutcome::unwritable;
  } else {
    depth_response_ = std::make_unique<const DepthResponse>(measure());
    response_kept_ = false;
    note = source.folder.empty() ? "depth response measured"
                                 : "depth response measured, not kept: this executable has no build ID";
  }
  response_note_ = note + "; " + depth_response_->summary();
}

void PairProcessor::take_deferred_depth_response(const PairProgress& progress) const {
  if (!response_deferred_) return;
  // call_once: a call that throws (a caller gave up) leaves it to the next. A response the
  // settings cannot have (InputError: a layer that does not follow the shifts) is refused once and
  // for every pair after, not measured again by each.
  std::call_once(response_once_, [&] {
    try {
      take_depth_response([&](double fraction) {
        if (progress) progress(std::string(kDeferredDepthResponseStage), fraction);
      });
    } catch (const InputError& e) {
      response_refused_ = e.what();
    }
  });
  if (!response_refused_.empty()) throw InputError(response_refused_);
}

PairResult PairProcessor::corrected(PairResult result) const {
  VectorField& field = result.correlation.field;
  if (depth_response_)
    depth_response_->apply(field);
  else if (field.has_sigma())
    field.sigma_method +=
        "; not MART's own error, which both volumes share: on reconstructed volumes a floor "
        "(docs/accuracy.md; reconstruction.depth_response_ppm calibrates it)";
  return result;
}

PairResult PairProcessor::process(const ImageU16& frame_a, const ImageU16& frame_b, const PairOptions& options) const {
  take_deferred_depth_response(options.progress);
  return corrected(process_uncorrected(frame_a, frame_b, options));
}

PairResult PairProcessor::process(const ImageF& frame_a, const ImageF& frame_b, const PairOptions& options) const {
  take_deferred_depth_response(options.progress);
  return corrected(process_uncorrected(frame_a, frame_b, options));
}

template <typename Frame>
const ImageF& PairProcessor::prepared(const Frame& frame, const BlackLevels& levels, ImageF& scratch) const {
  if constexpr (std::is_same_v<Frame, ImageF>) {
    if (settings_.pixel_binning == 1 && levels.nothing()) return frame;
  }
  scratch = bin_pixels(frame, settings_.pixel_binning);
  subtract_black_level(scratch, levels);
  return scratch;
}

PairResult PairProcessor::process_uncorrected(const ImageU16& frame_a, const ImageU16& frame_b,
                                              const PairOptions& options) const {
  // Counts are finite and non-negative: only the size is checked raw, and the frames are binned
  // straight from their counts (no sensor-sized float copy).
  recon::validate_size(frame_a.width, frame_a.height, raw_width_, raw_height_, "frame A");
  recon::validate_size(frame_b.width, frame_b.height, raw_width_, raw_height_, "frame B");
  const std::array<BlackLevels, 2> levels{black_level_.measure(frame_a), black_level_.measure(frame_b)};
  ImageF scratch_a, scratch_b;
  return run(prepared(frame_a, levels[0], scratch_a), prepared(frame_b, levels[1], scratch_b), options, levels);
}

PairResult PairProcessor::process_uncorrected(const ImageF& frame_a, const ImageF& frame_b,
                                              const PairOptions& options) const {
  recon::validate_image(frame_a, raw_width_, raw_height_, "frame A");
  recon::validate_image(frame_b, raw_width_, raw_height_, "frame B");
  const std::array<BlackLevels, 2> levels{black_level_.measure(frame_a), black_level_.measure(frame_b)};
  ImageF scratch_a, scratch_b;
  return run(prepared(frame_a, levels[0], scratch_a), prepared(frame_b, levels[1], scratch_b), options, levels);
}

std::size_t PairProcessor::reserve_workspaces(int pairs) const {
  const recon::WeightingOperator& weights = op_->weights();
  workspaces_.reserve(pairs, [&](PairWorkspace& workspace) {
    workspace.mart.reserve(weights);
    workspace.correlation.reserve(weights.grid().count());
  });
  return workspaces_.bytes();
}

PairResult PairProcessor::run(const ImageF& frame_a, const ImageF& frame_b, const PairOptions& options,
                              std::array<BlackLevels, 2> black_levels) const {
  ProcessSettings s = settings_;
  s.correlation.dt_s = pair_dt_s(settings_, options.measured_dt_s);
  const WorkspacePool::Lease workspace = workspaces_.take();
  PairResult result =
      process_pair(*op_, frame_a, frame_b, s, options.progress, &(*workspace).mart, &(*workspace).correlation);
  result.black_level_a = std::move(black_levels[0]);
  result.black_level_b = std::move(black_levels[1]);
  return result;
}

}  // namespace plenopiv::process
