// MART's numerical guards and small per-pixel helpers, shared by the simultaneous solver, the
// active-voxel selection and the row-action reference. Internal to core/recon.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

#include "core/base/big_buffer.hpp"

namespace plenopiv::recon::detail {

// Bounds that keep every value finite and normal in float: log-ratios beyond ±kMaxLog carry no
// information a reconstruction needs, and values under kTiny are flushed to zero (no denormals).
inline constexpr float kMaxLog = 40.f;
inline constexpr float kTiny = 1e-30f;
inline constexpr float kHuge = 1e30f;

// ln I for the pixels MART uses (0 elsewhere: those pixels see no active voxel).
inline float log_pixel(float v) { return v > 0.f ? std::log(std::max(v, kTiny)) : 0.f; }

inline std::vector<float> log_image(std::span<const float> image) {
  std::vector<float> out(image.size());
  for (std::size_t i = 0; i < image.size(); ++i) out[i] = log_pixel(image[i]);
  return out;
}

inline float bounded_exp(float x) { return std::exp(std::clamp(x, -kMaxLog, kMaxLog)); }

inline float clean(float v) { return v < kTiny ? 0.f : std::min(v, kHuge); }

inline double sum(std::span<const float> a) {
  double s = 0;
  for (float v : a) s += v;
  return s;
}

// f(i0, i1) over [0, n) in parallel chunks of pixels.
template <typename F>
void for_pixels(std::size_t n, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 14),
                    [&](const tbb::blocked_range<std::size_t>& r) { f(r.begin(), r.end()); });
}

// `b` with n elements that the caller writes before reading: its storage is kept when large
// enough, and nothing is copied into new storage when not.
template <typename T>
void fit(BigBuffer<T>& b, std::size_t n) {
  b.clear();
  b.resize(n);
}

}  // namespace plenopiv::recon::detail
