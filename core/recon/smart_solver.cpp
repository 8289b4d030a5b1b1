// The simultaneous MART of one image, step by step (setup, start, iterate, accelerate).
#include "core/recon/smart_solver.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <utility>

#include "core/recon/kernels.hpp"
#include "core/recon/mart_numerics.hpp"

namespace plenopiv::recon::detail {
namespace {

// SmartSolver::prune rebuilds the active set once 1 / kRebuildShare of its voxels are zero.
constexpr std::size_t kRebuildShare = 8;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The brick of local_prune_bricks(`voxels`) that holds voxel `column` (x + y * nx) of slice z.
std::size_t brick_of(const Grid3& bricks, const Grid3& voxels, std::size_t column, int z) {
  const std::size_t nx = std::size_t(voxels.shape[0]);
  return bricks.index(int(column % nx) / kLocalPruneBrick[0], int(column / nx) / kLocalPruneBrick[1],
                      z / kLocalPruneBrick[2]);
}

}  // namespace

SmartSolver::SmartSolver(const WeightingOperator& op, const MartSettings& settings, MartBuffers& buffers)
    : op_(op),
      settings_(settings),
      b_(buffers),
      active_(buffers.active),
      white_(op.white().pixels.data()),
      blur_(op, settings.sensor_blur_sigma_mm) {}

template <typename F>
void SmartSolver::for_voxel_ranges(F&& f) const {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_, 1 << 12),
                    [&](const tbb::blocked_range<std::size_t>& r) { f(r.begin(), r.end()); });
}

template <typename F>
void SmartSolver::for_voxels(F&& f) const {
  for_voxel_ranges([&](std::size_t m0, std::size_t m1) {
    for (std::size_t m = m0; m != m1; ++m) f(m);
  });
}

MartResult SmartSolver::run(const ImageF& image, const IterationCallback& progress) {
  const auto t_setup = std::chrono::steady_clock::now();
  setup(image);
  const auto t_start = std::chrono::steady_clock::now();
  start();
  result_.start_seconds = seconds_since(t_start);
  result_.setup_seconds = seconds_since(t_setup);
  prepare_iterations();
  if (settings_.prune) prune(false);

  int momentum_step = 1;  // k of FISTA's beta_k
  double previous = -1;   // the last iteration's residual
  for (int it = 1; it <= settings_.iterations && n_ > 0; ++it) {
    const auto t_it = std::chrono::steady_clock::now();
    if (settings_.accelerate) extrapolate(float(momentum_step - 1) / float(momentum_step + 2));
    project_and_compare(true);
    const double r = residual();
    if (previous >= 0 && settings_.convergence > 0 && std::abs(previous - r) <= settings_.convergence * previous) {
      result_.converged = true;
      if (settings_.accelerate) b_.e = b_.last;  // x_k, not the extrapolated point
      break;
    }
    previous = r;
    update();
    if (settings_.accelerate) momentum_step = step_along_momentum() ? momentum_step + 1 : 1;
    result_.skipped.voxel_updates += n_;
    result_.skipped.iterations = it;
    result_.skipped.work_done += active_.pass_work();
    result_.skipped.work_unpruned += start_work_;
    const std::size_t updated = n_;
    const double work = start_work_ > 0 ? active_.pass_work() / start_work_ : 1.0;
    if (settings_.prune) prune(it == settings_.iterations);
    IterationReport rep{it, r, seconds_since(t_it), updated, op_.grid().count(), work};
    result_.iterations.push_back(rep);
    if (progress) progress(rep);
  }
  if (settings_.final_residual) {
    if (n_ > 0) {
      project_and_compare(false);
      result_.final_residual = residual();
    } else {
      result_.final_residual = sum(b_.data) > 0 ? 1.0 : 0.0;  // nothing projected: ||I - 0|| / ||I||
    }
  }
  write_volume();
  return std::move(result_);
}

void SmartSolver::setup(const ImageF& image) {
  const auto t0 = std::chrono::steady_clock::now();
  result_.volume = Volume(op_.grid(), 0.f);
  threshold_image(image, settings_.noise_threshold, b_.data);
  // Built in the storage the last assign() handed back (the previous frame's list, or one pruning
  // replaced): from the third set on, both lists are as large as a frame's and in memory.
  select_active(op_, b_.data, settings_, b_.select, result_.skipped, b_.next_voxels);
  result_.select_seconds = seconds_since(t0);
  const auto t_active = std::chrono::steady_clock::now();
  active_.assign(op_, b_.next_voxels);
  result_.active_set_seconds = seconds_since(t_active);
  n_ = n_start_ = active_.size();
  start_work_ = active_.pass_work();
  fit(b_.origin, n_);
  for_voxels([&](std::size_t m) { b_.origin[m] = std::uint32_t(m); });
}

void SmartSolver::start() {
  // Per active voxel; BigBuffers (huge pages: no page fault per 4 KB of these large arrays).
  // `update` is written in full by every back-projection.
  b_.e.assign(n_, 1.f);
  fit(b_.update, n_);
  // Written in full by every pass before being read.
  fit(b_.projection, op_.pixel_count());

  // What a dark pixel recorded at most: the caller's (a resampled frame's raw floor), else the
  // noise threshold, or half the faintest lit pixel.
  dark_floor_ = settings_.dark_floor > 0.f ? settings_.dark_floor : dark_floor_of(b_.data, settings_.noise_threshold);
  result_.skipped.dark_floor = dark_floor_;
  if (settings_.start == MartStart::mlos && n_ > 0) start_mlos();
}

void SmartSolver::start_mlos() {
  const BigBuffer<float>& data = b_.data;
  BigBuffer<float>& e = b_.e;
  // The weighted geometric mean of the pixels a voxel sees (multiplicative line of sight), each
  // dark pixel at the floor it recorded at most, as the iterations take it (ratio_band): ln E_j =
  // Σ_i W_ij white_i ln max(I_i, floor) / n_j, one back-projection of ln I times the white image
  // (in the projection buffer, not yet in use). n_j = Σ_i W_ij white_i, so an image scaled by c
  // scales every voxel by c, which the scale to the image's light below undoes. The floor's log is
  // bounded as a lit pixel's is (ln max(I, kTiny)): half the faintest pixel of an image near the
  // float limit can round to 0. The logarithms and exponentials are SLEEF's, as the iterations'
  // (kernels::log_pixels, multiply_by_exp): the same start on every x86-64 CPU.
  const float floor_or_tiny = std::max(dark_floor_, kTiny);
  float log_floor = 0;
  kernels::log_or_zero(&floor_or_tiny, 0, 1, &log_floor);
  for_pixels(data.size(), [&](std::size_t i0, std::size_t i1) {
    kernels::log_pixels(data.data(), white_, log_floor, kTiny, i0, i1, b_.projection.data());
  });
  active_.back_project_whitened(op_, b_.projection, b_.update, &b_.kernels);
  // E = exp(ln E); a voxel that sees no pixel (n_j = 0) is left out of the passes and stays 0.
  const BigBuffer<std::uint32_t>& voxels = active_.voxels();
  for_voxels([&](std::size_t m) { e[m] = op_.normaliser(voxels[m]) > 0.f ? 1.f : 0.f; });
  // Raised to mlos_power: exp(p ln E), the same kernel with p in mu's place. Above 1, ln E less
  // its largest value first, so that no exponent reaches kMaxLog at the bright end whatever the
  // image's units (the scale to the image's light below undoes any constant factor).
  if (settings_.mlos_power != 1.0) {
    const float peak = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, n_, 1 << 14), -std::numeric_limits<float>::infinity(),
        [&](const tbb::blocked_range<std::size_t>& r, float p) {
          for (std::size_t m = r.begin(); m != r.end(); ++m)
            if (e[m] != 0.f) p = std::max(p, b_.update[m]);
          return p;
        },
        [](float a, float b) { return std::max(a, b); });
    if (std::isfinite(peak)) for_voxels([&](std::size_t m) { b_.update[m] -= peak; });
  }
  const kernels::MultiplicativeUpdate start{e.data(), b_.update.data(), float(settings_.mlos_power), kMaxLog, kTiny,
                                            kHuge};
  for_voxel_ranges([&](std::size_t m0, std::size_t m1) { kernels::multiply_by_exp(start, m0, m1); });
  // Scale to the image's total light so the first ratios are near 1. The projection's total is
  // Σ_j E_j (eq 13 makes each voxel's weights sum to 1 over the sensor), so no projection is
  // needed; the two totals differ by the projection's float rounding only (docs/recon.md,
  // "Buffers").
  const double total = sum(e);
  if (total > 0) {
    const float scale = float(sum(data) / total);
    for_voxels([&](std::size_t m) { e[m] = clean(e[m] * scale); });
  }
}

void SmartSolver::prepare_iterations() {
  // ln I and ln floor once, not per iteration.
  const BigBuffer<float>& data = b_.data;
  BigBuffer<float>& log_data = b_.log_data;
  fit(log_data, data.size());
  // The log-ratios' logarithm (kernels::log_ratios), so that a pixel its projection matches
  // exactly has a log-ratio of exactly 0.
  for_pixels(data.size(),
             [&](std::size_t i0, std::size_t i1) { kernels::log_or_zero(data.data(), i0, i1, log_data.data()); });
  // ln floor with the same logarithm: the dark pixels' log-ratios subtract ln P from it. A floor
  // below kTiny (an image whose faintest pixel is a denormal) as kTiny: its log-ratios are at their
  // bound either way.
  const float floor_or_tiny = std::max(dark_floor_, kTiny);
  kernels::log_or_zero(&floor_or_tiny, 0, 1, &log_floor_);
  // The residual's two sums per band of the projection, added in band order: the same at any
  // thread count.
  band_sums_.assign(std::size_t(active_.band_count()), {0.0, 0.0});
  // Nesterov's momentum on ln E: `last` holds x_(k-1), then x_k; `log_last` its ln (kept, so
  // each iteration takes one log per voxel, not two); `momentum` ln x_k - ln x_(k-1) (0 where
  // either is 0).
  if (settings_.accelerate) {
    b_.last.assign(b_.e.begin(), b_.e.end());
    b_.log_last.resize(n_);  // written in full here
    for_voxel_ranges(
        [&](std::size_t m0, std::size_t m1) { kernels::log_or_zero(b_.last.data(), m0, m1, b_.log_last.data()); });
    b_.momentum.assign(n_, 0.f);
  }
}

void SmartSolver::extrapolate(float beta) {
  // Each iteration starts from y = x_k (x_k / x_(k-1))^beta_k with FISTA's
  // beta_k = (k - 1) / (k + 2).
  const kernels::Extrapolation x{b_.e.data(), b_.last.data(), b_.log_last.data(), b_.momentum.data(), beta, kMaxLog,
                                 kTiny,       kHuge};
  for_voxel_ranges([&](std::size_t m0, std::size_t m1) { kernels::extrapolate(x, m0, m1); });
}

void SmartSolver::residual_band(int band, std::size_t i0, std::size_t i1) {
  const BigBuffer<float>& data = b_.data;
  double num = 0, den = 0;
  for (std::size_t i = i0; i < i1; ++i) {
    const double diff = double(data[i]) - double(b_.projection[i]);
    num += diff * diff;
    den += double(data[i]) * double(data[i]);
  }
  band_sums_[std::size_t(band)] = {num, den};
}

double SmartSolver::residual() const {
  double num = 0, den = 0;
  for (const auto& b : band_sums_) {
    num += b[0];
    den += b[1];
  }
  return den > 0 ? std::sqrt(num / den) : 0.0;
}

// The log-ratio of each pixel MART uses, times `scale` (the white image, or 1 where the sensor
// blur is applied before whitening), in place of the pixel's projection.
void SmartSolver::ratio_band(std::size_t i0, std::size_t i1, const float* scale) {
  const kernels::LogRatioInputs in{
      b_.projection.data(), b_.data.data(), b_.log_data.data(), white_, scale, kMaxLog, log_floor_, dark_floor_, kTiny};
  kernels::log_ratios(in, i0, i1, b_.projection.data());
}

void SmartSolver::project_and_compare(bool with_ratio) {
  // Without blur, each band is finished while its pixels are in cache; with it, the whole
  // projection must exist before the blur.
  if (!blur_.active()) {
    active_.project(op_, b_.e, b_.projection, &b_.kernels, [&](int band, std::size_t i0, std::size_t i1) {
      residual_band(band, i0, i1);
      if (with_ratio) ratio_band(i0, i1, white_);
    });
    return;
  }
  active_.project(op_, b_.e, b_.projection, &b_.kernels);
  blur_.apply(b_.projection);
  // The residual's sums in fixed pixel bands (the projection's own bands no longer apply).
  const std::size_t pixels = b_.data.size();
  const std::size_t bands = band_sums_.size(), per_band = (pixels + bands - 1) / bands;
  tbb::parallel_for(std::size_t(0), bands, [&](std::size_t b) {
    residual_band(int(b), std::min(pixels, b * per_band), std::min(pixels, (b + 1) * per_band));
  });
  if (!with_ratio) return;
  for_pixels(pixels, [&](std::size_t i0, std::size_t i1) { ratio_band(i0, i1, nullptr); });
  blur_.apply(b_.projection);
  for_pixels(pixels, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) b_.projection[i] *= white_[i];
  });
}

void SmartSolver::update() {
  // The log-ratios project_and_compare(true) left in the projection's buffer.
  active_.back_project_whitened(op_, b_.projection, b_.update, &b_.kernels);
  const kernels::MultiplicativeUpdate u{b_.e.data(), b_.update.data(), float(settings_.mu), kMaxLog, kTiny, kHuge};
  for_voxel_ranges([&](std::size_t m0, std::size_t m1) { kernels::multiply_by_exp(u, m0, m1); });
}

bool SmartSolver::step_along_momentum() const {
  // Does this step (ln x_(k+1) - ln y = mu * update) go along the momentum? Summed over a fixed
  // tree of the start's active set, as tbb::parallel_deterministic_reduce sums a range with grain
  // kGrain: halves until a range is no longer than the grain, each leaf from 0 in order, then left
  // + right. So the answer is the same at any thread count, and pruning changes no bit: a pruned
  // voxel's term was update x 0 = ±0, which leaves a sum as it was.
  constexpr std::size_t kGrain = std::size_t(1) << 14;
  std::vector<std::array<std::size_t, 2>> leaves;  // [begin, end) in start positions
  auto split = [&](auto&& self, std::size_t begin, std::size_t end) -> void {
    if (end - begin > kGrain) {
      const std::size_t mid = begin + (end - begin) / 2;
      self(self, begin, mid);
      self(self, mid, end);
    } else {
      leaves.push_back({begin, end});
    }
  };
  split(split, 0, n_start_);
  std::vector<double> leaf_sum(leaves.size());
  const std::uint32_t* origin = b_.origin.data();
  tbb::parallel_for(std::size_t(0), leaves.size(), [&](std::size_t k) {
    const std::size_t m0 = std::size_t(std::lower_bound(origin, origin + n_, leaves[k][0]) - origin);
    const std::size_t m1 = std::size_t(std::lower_bound(origin, origin + n_, leaves[k][1]) - origin);
    double acc = 0.0;
    for (std::size_t m = m0; m < m1; ++m) acc += double(b_.update[m]) * double(b_.momentum[m]);
    leaf_sum[k] = acc;
  });
  std::size_t next = 0;
  auto combine = [&](auto&& self, std::size_t begin, std::size_t end) -> double {
    if (end - begin > kGrain) {
      const std::size_t mid = begin + (end - begin) / 2;
      const double left = self(self, begin, mid);
      return left + self(self, mid, end);
    }
    return leaf_sum[next++];
  };
  return !(combine(combine, 0, n_start_) < 0);
}

void SmartSolver::prune(bool last) {
  const auto t0 = std::chrono::steady_clock::now();
  struct Timer {
    std::chrono::steady_clock::time_point t0;
    double& total;
    ~Timer() { total += seconds_since(t0); }
  } timer{t0, result_.prune_seconds};
  BigBuffer<float>& e = b_.e;
  if (n_ == 0) return;
  if (settings_.prune_threshold > 0 || settings_.prune_local_threshold > 0) zero_below_cut();
  const std::size_t dead = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, n_, 1 << 14), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& r, std::size_t count) {
        for (std::size_t m = r.begin(); m != r.end(); ++m) count += e[m] == 0.f;
        return count;
      },
      std::plus<std::size_t>());
  // A zero costs a pass a little work (its column's blocks stay while any voxel there lives); a
  // new layout costs about what the smaller set saves over the iterations left, whether sooner
  // or later (docs/lab/2026-11-28.md). Rebuild once 1 / kRebuildShare of the set is zero.
  if (dead == 0 || dead * kRebuildShare < n_) return;
  // After the last iteration no pass follows but the final residual's projection, which skips
  // zeros: the zeros are written to the volume as they are, and counted as the rebuild would.
  if (last) {
    result_.skipped.voxels_pruned += dead;
    return;
  }
  const BigBuffer<std::uint32_t>& old_voxels = active_.voxels();  // read before assign()
  BigBuffer<std::uint32_t>& voxels = b_.next_voxels;
  voxels.clear();
  voxels.reserve(n_ - dead);
  // Compacted in place, in order: position m' <= m, so nothing is overwritten before it is read.
  std::size_t live = 0;
  for (std::size_t m = 0; m < n_; ++m) {
    if (e[m] == 0.f) continue;
    voxels.push_back(old_voxels[m]);
    e[live] = e[m];
    b_.origin[live] = b_.origin[m];
    if (settings_.accelerate) {
      b_.last[live] = b_.last[m];
      b_.log_last[live] = b_.log_last[m];
      b_.momentum[live] = b_.momentum[m];
    }
    ++live;
  }
  result_.skipped.voxels_pruned += n_ - live;
  n_ = live;
  for (BigBuffer<float>* b : {&b_.e, &b_.update}) b->resize(n_);
  b_.origin.resize(n_);
  if (settings_.accelerate) {
    for (BigBuffer<float>* b : {&b_.last, &b_.log_last, &b_.momentum}) b->resize(n_);
  }
  active_.assign(op_, voxels);
}

void SmartSolver::zero_below_cut() {
  BigBuffer<float>& e = b_.e;
  // Each depth slice's live voxels: [run[z], run[z + 1]).
  const BigBuffer<std::uint32_t>& voxels = active_.voxels();
  const int depth = op_.grid().shape[2];
  const std::size_t slice = std::size_t(op_.grid().shape[0]) * op_.grid().shape[1];
  const std::vector<std::size_t> run = active_.slice_runs(op_);
  // The cut per slice: the threshold times the slice's peak, or the volume's (the peak of the
  // slices' peaks; a maximum is the same in any order).
  std::vector<float> cut(std::size_t(depth), 0.f);
  tbb::parallel_for(0, depth, [&](int z) {
    for (std::size_t m = run[z]; m < run[z + 1]; ++m) cut[z] = std::max(cut[z], e[m]);
  });
  if (settings_.prune_scope == PruneScope::volume)
    std::fill(cut.begin(), cut.end(), *std::max_element(cut.begin(), cut.end()));
  for (float& c : cut) c = float(settings_.prune_threshold * double(c));
  const bool local = settings_.prune_local_threshold > 0;
  const Grid3 bricks = local_prune_bricks(op_.grid());
  if (local) local_peaks(run, bricks);
  const float local_share = float(settings_.prune_local_threshold);
  // Voxel m's cut (it lies in slice z): its slice's, or its neighbourhood's where that is higher.
  auto cut_of = [&](std::size_t m, int z) {
    if (!local) return cut[std::size_t(z)];
    const std::size_t column = voxels[m] - std::size_t(z) * slice;  // x + y * nx
    return std::max(cut[std::size_t(z)], local_share * b_.local_peak[brick_of(bricks, op_.grid(), column, z)]);
  };

  const int reach = settings_.prune_depth_reach;
  if (reach == 0) {
    tbb::parallel_for(0, depth, [&](int z) {
      for (std::size_t m = run[z]; m < run[z + 1]; ++m)
        if (e[m] <= cut_of(m, z)) e[m] = 0.f;
    });
    return;
  }
  // A voxel at or below its cut stays while one of the `reach` voxels before or after it along
  // depth is above theirs.
  BigBuffer<std::uint8_t>& above = b_.above_cut;
  above.resize(slice * std::size_t(depth));
  tbb::parallel_for(0, depth, [&](int z) {
    std::fill(above.begin() + std::ptrdiff_t(std::size_t(z) * slice),
              above.begin() + std::ptrdiff_t(std::size_t(z + 1) * slice), std::uint8_t(0));
    for (std::size_t m = run[z]; m < run[z + 1]; ++m)
      if (e[m] > cut_of(m, z)) above[voxels[m]] = 1;
  });
  tbb::parallel_for(0, depth, [&](int z) {
    const int z0 = std::max(0, z - reach), z1 = std::min(depth - 1, z + reach);
    for (std::size_t m = run[z]; m < run[z + 1]; ++m) {
      if (e[m] > cut_of(m, z)) continue;
      const std::size_t column = voxels[m] - std::size_t(z) * slice;  // x + y * nx
      bool near = false;
      for (int zz = z0; zz <= z1 && !near; ++zz) near = above[column + std::size_t(zz) * slice] != 0;
      if (!near) e[m] = 0.f;
    }
  });
}

void SmartSolver::local_peaks(const std::vector<std::size_t>& run, const Grid3& bricks) {
  const int bz = kLocalPruneBrick[2], depth = op_.grid().shape[2];
  const std::size_t slice = std::size_t(op_.grid().shape[0]) * std::size_t(op_.grid().shape[1]);
  const BigBuffer<std::uint32_t>& voxels = active_.voxels();
  BigBuffer<float>& peak = b_.local_peak;
  BigBuffer<float>& spread = b_.local_scratch;
  peak.assign(bricks.count(), 0.f);
  spread.resize(bricks.count());
  // One task per layer of bricks (kLocalPruneBrick[2] slices): no two tasks write one brick.
  tbb::parallel_for(0, bricks.shape[2], [&](int k) {
    for (int z = k * bz; z < std::min(depth, (k + 1) * bz); ++z) {
      for (std::size_t m = run[std::size_t(z)]; m < run[std::size_t(z) + 1]; ++m) {
        float& p = peak[brick_of(bricks, op_.grid(), voxels[m] - std::size_t(z) * slice, z)];
        p = std::max(p, b_.e[m]);
      }
    }
  });
  // Each brick takes the peak of its neighbours along one axis, then the next: after the three,
  // of the 27 bricks about it (a maximum is the same in any order).
  auto along = [&](int axis, const BigBuffer<float>& from, BigBuffer<float>& to) {
    tbb::parallel_for(0, bricks.shape[2], [&](int k) {
      for (int j = 0; j < bricks.shape[1]; ++j) {
        for (int i = 0; i < bricks.shape[0]; ++i) {
          float p = 0.f;
          for (int d = -1; d <= 1; ++d) {
            std::array<int, 3> at{i, j, k};
            at[axis] += d;
            if (at[axis] < 0 || at[axis] >= bricks.shape[axis]) continue;
            p = std::max(p, from[bricks.index(at[0], at[1], at[2])]);
          }
          to[bricks.index(i, j, k)] = p;
        }
      }
    });
  };
  along(0, peak, spread);
  along(1, spread, peak);
  along(2, peak, spread);
  peak.swap(spread);
}

Grid3 local_prune_bricks(const Grid3& voxels) {
  Grid3 bricks = voxels;
  for (int a = 0; a < 3; ++a) {
    bricks.shape[a] = (voxels.shape[a] + kLocalPruneBrick[a] - 1) / kLocalPruneBrick[a];
    bricks.spacing_mm[a] = voxels.spacing_mm[a] * kLocalPruneBrick[a];
    bricks.origin_mm[a] = voxels.origin_mm[a] + 0.5 * (kLocalPruneBrick[a] - 1) * voxels.spacing_mm[a];
  }
  return bricks;
}

void SmartSolver::write_volume() {
  const BigBuffer<std::uint32_t>& voxels = active_.voxels();
  // Distinct voxels: no two writes to one value.
  for_voxels([&](std::size_t m) { result_.volume.data[voxels[m]] = b_.e[m]; });
}

}  // namespace plenopiv::recon::detail
