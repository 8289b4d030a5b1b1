// MART on the plenoptic weights: the settings' and image's checks, the sensor blur, the kept
// workspace, the simultaneous reconstruction (smart_solver.cpp) and the row-action reference of
// eq 9.
#include "core/recon/mart.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>

#include "core/base/enum_names.hpp"
#include "core/base/errors.hpp"
#include "core/recon/mart_numerics.hpp"
#include "core/recon/sensor_blur.hpp"
#include "core/recon/smart_solver.hpp"
#include "core/recon/voxel_selection.hpp"

namespace plenopiv::recon {
namespace {

using detail::bounded_exp;
using detail::clean;
using detail::kMaxLog;
using detail::log_image;
using detail::sum;

void check_sensor_blur_sigma(double sigma_mm, const char* who) {
  if (!(sigma_mm >= 0 && sigma_mm <= kMaxSensorBlurSigmaMm)) {
    throw InputError(std::string(who) + ": sensor blur sigma must lie in [0, " + std::to_string(kMaxSensorBlurSigmaMm) +
                     "] mm, got " + std::to_string(sigma_mm));
  }
}

void validate_settings(const MartSettings& s) {
  if (const auto problem = check(s)) throw InputError("MART: " + problem->key + ": " + problem->reason);
}

}  // namespace

std::string_view name_of(MartStart start) { return name_in(kMartStartNames, start); }
std::string_view name_of(PruneScope scope) { return name_in(kPruneScopeNames, scope); }

MartStart mart_start_named(std::string_view name, std::string_view what) {
  return value_named<MartStart>(kMartStartNames, name, what);
}

PruneScope prune_scope_named(std::string_view name, std::string_view what) {
  return value_named<PruneScope>(kPruneScopeNames, name, what);
}

std::optional<SettingProblem> check(const MartSettings& s) {
  const auto number = [](double v) { return std::to_string(v); };
  if (s.iterations < 1 || s.iterations > 10000) {
    return SettingProblem{"iterations", "must be 1 to 10000, got " + std::to_string(s.iterations)};
  }
  if (!(s.mu > 0 && s.mu <= 1)) return SettingProblem{"mu", "must be in (0, 1], got " + number(s.mu)};
  if (!(s.mlos_power >= 1 && s.mlos_power <= kMaxMlosPower)) {
    return SettingProblem{"mlos_power", "must be in [1, " + number(kMaxMlosPower) + "], got " + number(s.mlos_power)};
  }
  if (s.mlos_power != 1 && s.start != MartStart::mlos) {
    return SettingProblem{"mlos_power", "raises the mlos start; with start: " + std::string(name_of(s.start)) +
                                            " it must be 1, got " + number(s.mlos_power)};
  }
  if (!(s.noise_threshold >= 0) || !std::isfinite(s.noise_threshold)) {
    return SettingProblem{"noise_threshold", "must be a finite number >= 0 counts, got " + number(s.noise_threshold)};
  }
  if (!(s.dark_floor >= 0) || !std::isfinite(s.dark_floor)) {
    return SettingProblem{"dark_floor", "must be a finite number >= 0 counts, got " + number(s.dark_floor)};
  }
  if (!(s.dark_weight_cutoff >= 0 && s.dark_weight_cutoff < 1)) {
    return SettingProblem{"dark_weight_cutoff", "must be in [0, 1), got " + number(s.dark_weight_cutoff)};
  }
  if (!(s.convergence >= 0) || !std::isfinite(s.convergence)) {
    return SettingProblem{"convergence", "must be a finite number >= 0, got " + number(s.convergence)};
  }
  if (!(s.sensor_blur_sigma_mm >= 0 && s.sensor_blur_sigma_mm <= kMaxSensorBlurSigmaMm)) {
    return SettingProblem{"sensor_blur_sigma_mm", "must be in [0, " + number(kMaxSensorBlurSigmaMm) + "] mm, got " +
                                                      number(s.sensor_blur_sigma_mm)};
  }
  if (!(s.prune_threshold >= 0 && s.prune_threshold < 1)) {
    return SettingProblem{"prune_threshold",
                          "must be in [0, 1) (a fraction of the volume's peak), got " + number(s.prune_threshold)};
  }
  if (!(s.prune_local_threshold >= 0 && s.prune_local_threshold < 1)) {
    return SettingProblem{"prune_local_threshold", "must be in [0, 1) (a fraction of the neighbourhood's peak), got " +
                                                       number(s.prune_local_threshold)};
  }
  if (!(s.prune_depth_reach >= 0 && s.prune_depth_reach <= kMaxPruneDepthReach)) {
    return SettingProblem{"prune_depth_reach", "must be in [0, " + std::to_string(kMaxPruneDepthReach) +
                                                   "] depth slices, got " + std::to_string(s.prune_depth_reach)};
  }
  return std::nullopt;
}

void apply_sensor_blur(const WeightingOperator& op, double sigma_mm, std::span<float> image) {
  check_sensor_blur_sigma(sigma_mm, "apply_sensor_blur");
  if (image.size() != op.pixel_count()) throw InputError("sensor blur: the image is not the operator's sensor");
  detail::SensorBlur blur(op, sigma_mm);
  if (blur.active()) blur.apply(image);
}

void validate_image(const ImageF& image, const WeightingOperator& op, const char* source) {
  validate_image(image, op.image_width(), op.image_height(), source);
}

void validate_size(int image_width, int image_height, int width, int height, const char* source) {
  if (image_width != width || image_height != height) {
    throw InputError(std::string(source) + ": image is " + std::to_string(image_width) + " x " +
                     std::to_string(image_height) + " px, the camera's sensor is " + std::to_string(width) + " x " +
                     std::to_string(height));
  }
}

void validate_image(const ImageF& image, int width, int height, const char* source) {
  validate_size(image.width, image.height, width, height, source);
  // Checked in parallel; only an image that fails is scanned again in order to name its first
  // bad pixel.
  std::atomic<bool> bad{false};
  detail::for_pixels(image.pixels.size(), [&](std::size_t i0, std::size_t i1) {
    bool chunk_bad = false;
    for (std::size_t i = i0; i < i1; ++i) {
      const float v = image.pixels[i];
      chunk_bad |= !(v >= 0.f && v <= detail::kHuge);  // NaN fails both
    }
    if (chunk_bad) bad.store(true, std::memory_order_relaxed);
  });
  if (!bad.load()) return;
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    const float v = image.pixels[i];
    if (!std::isfinite(v) || v < 0.f) {
      throw InputError(std::string(source) + ": pixel (" + std::to_string(i % std::size_t(image.width)) + ", " +
                       std::to_string(i / std::size_t(image.width)) + ") is " + std::to_string(v) +
                       "; intensities must be finite and non-negative");
    }
    if (v > detail::kHuge) {
      throw InputError(std::string(source) + ": pixel value " + std::to_string(v) + " exceeds " +
                       std::to_string(detail::kHuge) + "; scale the image down");
    }
  }
}

MartWorkspace::MartWorkspace() : buffers_(std::make_unique<detail::MartBuffers>()) {}
MartWorkspace::~MartWorkspace() = default;
MartWorkspace::MartWorkspace(MartWorkspace&&) noexcept = default;
MartWorkspace& MartWorkspace::operator=(MartWorkspace&&) noexcept = default;

std::size_t MartWorkspace::bytes() const {
  if (!buffers_) return 0;  // moved from
  const detail::MartBuffers& b = *buffers_;
  std::size_t total = 0;
  for (const auto* v : {&b.data, &b.log_data, &b.projection, &b.e, &b.update, &b.last, &b.log_last, &b.momentum}) {
    total += v->capacity() * sizeof(float);
  }
  total += b.kernels.scaled.capacity() * sizeof(float) + b.kernels.sums.capacity() * sizeof(double);
  total += (b.kernels.band_lanes.capacity() + b.kernels.image_lanes.capacity()) * sizeof(float);
  total += b.select.dark.capacity() * sizeof(std::uint64_t) + b.origin.capacity() * sizeof(std::uint32_t);
  total += b.above_cut.capacity();
  total += b.active.bytes() + b.next_voxels.capacity() * sizeof(std::uint32_t);
  for (const auto& slice : b.select.per_slice) total += slice.capacity() * sizeof(std::uint32_t);
  return total;
}

void MartWorkspace::reserve(const WeightingOperator& op) {
  if (!buffers_) throw std::logic_error("MART: the workspace was moved from; use the one it was moved to");
  detail::MartBuffers& b = *buffers_;
  if (b.busy.exchange(true)) throw std::logic_error("MART: the workspace is in use by a reconstruction");
  struct Release {
    std::atomic<bool>& busy;
    ~Release() { busy.store(false); }
  } release{b.busy};
  // Every buffer at the largest size a reconstruction with `op` gives it, written once so that its
  // pages are in (assign fills; the kernels write their own scratch).
  const Grid3& g = op.grid();
  const std::size_t voxels = g.count(), pixels = op.pixel_count();
  BigBuffer<std::uint32_t> all(voxels);
  for (std::size_t i = 0; i < voxels; ++i) all[i] = std::uint32_t(i);
  b.active.assign(op, all);
  // The other list (ActiveSet::assign trades them) at the same size, its pages in.
  b.next_voxels.assign(voxels, 0);
  b.next_voxels.clear();
  for (BigBuffer<float>* v : {&b.e, &b.update, &b.last, &b.log_last, &b.momentum}) v->assign(voxels, 0.f);
  b.origin.assign(voxels, 0);
  b.above_cut.assign(voxels, 0);  // read only with MartSettings::prune_depth_reach, which reserve() does not know
  // Read only with MartSettings::prune_local_threshold.
  for (BigBuffer<float>* v : {&b.local_peak, &b.local_scratch}) v->assign(detail::local_prune_bricks(g).count(), 0.f);
  for (BigBuffer<float>* v : {&b.data, &b.log_data, &b.projection}) v->assign(pixels, 0.f);
  b.active.reserve(op, b.kernels);
  const std::size_t words = std::size_t(op.image_height() + 63) / 64;
  b.select.dark.assign(std::size_t(op.image_width()) * words, 0);
  b.select.per_slice.resize(std::size_t(g.shape[2]));
  for (auto& slice : b.select.per_slice) {
    slice.assign(std::size_t(g.shape[0]) * std::size_t(g.shape[1]), 0);
    slice.clear();
  }
}

float dark_floor_of(std::span<const float> image, float noise_threshold) {
  if (noise_threshold > 0.f) return noise_threshold;
  // A minimum: the same whatever the order.
  const float faintest = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, image.size(), 1 << 14), detail::kHuge,
      [&](const tbb::blocked_range<std::size_t>& r, float m) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          if (image[i] > 0.f) m = std::min(m, image[i]);
        }
        return m;
      },
      [](float a, float b) { return std::min(a, b); });
  return 0.5f * faintest;
}

MartResult reconstruct(const WeightingOperator& op, const ImageF& image, const MartSettings& settings,
                       const IterationCallback& progress) {
  MartWorkspace workspace;
  return reconstruct(op, image, settings, workspace, progress);
}

MartResult reconstruct(const WeightingOperator& op, const ImageF& image, const MartSettings& settings,
                       MartWorkspace& workspace, const IterationCallback& progress) {
  if (!workspace.buffers_) throw std::logic_error("MART: the workspace was moved from; use the one it was moved to");
  detail::MartBuffers& buffers = *workspace.buffers_;
  if (buffers.busy.exchange(true)) {
    throw std::logic_error(
        "MART: the workspace is in use by another reconstruction; give each concurrent "
        "reconstruction its own");
  }
  struct Release {
    std::atomic<bool>& busy;
    ~Release() { busy.store(false); }
  } release{buffers.busy};
  validate_settings(settings);
  validate_image(image, op, "image");
  if (settings.method != MartMethod::smart) {
    throw InputError(
        "MART: the matrix-free reconstruction runs the simultaneous form; the row-action "
        "form needs the explicit matrix (reconstruct_row_action)");
  }
  return detail::SmartSolver(op, settings, buffers).run(image, progress);
}

Volume reconstruct_row_action(const WeightingOperator& op, const SparseMatrix& w, const ImageF& image,
                              const MartSettings& settings) {
  validate_settings(settings);
  validate_image(image, op, "image");
  const Grid3& g = op.grid();
  if (w.rows != op.pixel_count() || w.cols != g.count()) {
    throw InputError("row-action MART: the matrix does not belong to this operator");
  }
  BigBuffer<float> data;
  detail::threshold_image(image, settings.noise_threshold, data);
  std::vector<float> e(g.count(), 1.f);
  if (settings.start == MartStart::mlos) {
    std::vector<float> logs(g.count(), 0.f);
    w.multiply_transpose(log_image(data), logs);
    // A voxel seen by a dark pixel starts (and stays) at zero.
    std::vector<char> dark(g.count(), 0);
    for (std::size_t i = 0; i < w.rows; ++i) {
      if (data[i] > 0.f) continue;
      for (std::size_t k = w.row_start[i]; k < w.row_start[i + 1]; ++k) dark[w.col_index[k]] = 1;
    }
    for (std::size_t j = 0; j < e.size(); ++j) e[j] = dark[j] ? 0.f : clean(bounded_exp(logs[j]));
    std::vector<float> p(w.rows, 0.f);
    w.multiply(e, p);
    const double total = sum(p);
    if (total > 0) {
      const float scale = float(sum(data) / total);
      for (float& v : e) v = clean(v * scale);
    }
  }
  for (int z = 0; z < g.shape[2]; ++z) {
    for (int y = 0; y < g.shape[1]; ++y) {
      for (int x = 0; x < g.shape[0]; ++x) {
        const std::size_t j = g.index(x, y, z);
        if (!detail::in_region(g, settings.region, x, y, z) || !(op.normaliser(j) > 0.f)) e[j] = 0.f;
      }
    }
  }
  const double mu = settings.mu;
  for (int it = 0; it < settings.iterations; ++it) {
    for (std::size_t i = 0; i < w.rows; ++i) {
      const std::size_t k0 = w.row_start[i], k1 = w.row_start[i + 1];
      if (k0 == k1) continue;
      double p = 0;
      for (std::size_t k = k0; k < k1; ++k) p += double(w.values[k]) * e[w.col_index[k]];
      if (data[i] == 0.f) {
        for (std::size_t k = k0; k < k1; ++k) e[w.col_index[k]] = 0.f;
        continue;
      }
      if (!(p > 0)) continue;
      const double log_ratio = std::clamp(std::log(double(data[i]) / p), -double(kMaxLog), double(kMaxLog));
      for (std::size_t k = k0; k < k1; ++k) {
        float& v = e[w.col_index[k]];
        v = clean(float(v * std::exp(mu * w.values[k] * log_ratio)));
      }
    }
  }
  Volume out(g);
  out.data.assign(e.begin(), e.end());
  return out;
}

}  // namespace plenopiv::recon
