// MART on the plenoptic weights: active-set selection (dark pixels, region, field of view),
// MLOS start, simultaneous multiplicative iterations, and the row-action reference of eq 9.
#include "core/recon/mart.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

#include "core/base/errors.hpp"

namespace plenopiv::recon {
namespace {

// Bounds that keep every value finite and normal in float: log-ratios beyond ±kMaxLog carry no
// information a reconstruction needs, and values under kTiny are flushed to zero (no denormals).
constexpr float kMaxLog = 40.f;
constexpr float kTiny = 1e-30f;
constexpr float kHuge = 1e30f;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void check_sensor_blur_sigma(double sigma_mm, const char* who) {
  if (!(sigma_mm >= 0 && sigma_mm <= kMaxSensorBlurSigmaMm)) {
    throw InputError(std::string(who) + ": sensor blur sigma must lie in [0, " + std::to_string(kMaxSensorBlurSigmaMm) +
                     "] mm, got " + std::to_string(sigma_mm));
  }
}

void validate_settings(const MartSettings& s) {
  if (!(s.mu > 0 && s.mu <= 1)) throw InputError("MART: mu must lie in (0, 1], got " + std::to_string(s.mu));
  if (s.iterations < 1 || s.iterations > 10000) {
    throw InputError("MART: iterations must be 1..10000, got " + std::to_string(s.iterations));
  }
  if (!(s.noise_threshold >= 0) || !std::isfinite(s.noise_threshold)) {
    throw InputError("MART: noise threshold must be a finite number >= 0");
  }
  if (!(s.dark_weight_cutoff >= 0 && s.dark_weight_cutoff < 1)) {
    throw InputError("MART: dark weight cutoff must lie in [0, 1)");
  }
  if (!(s.convergence >= 0) || !std::isfinite(s.convergence)) {
    throw InputError("MART: convergence tolerance must be a finite number >= 0");
  }
  check_sensor_blur_sigma(s.sensor_blur_sigma_mm, "MART");
}

// The sensor blur B of MartSettings::sensor_blur_sigma_mm on a whole sensor image, in place
// (light blurred off the sensor is lost, as on the camera). OpenCV's separable Gaussian: each
// output pixel is the same sum whatever the threads.
class SensorBlur {
 public:
  SensorBlur(const WeightingOperator& op, double sigma_mm)
      : width_(op.image_width()), height_(op.image_height()), sigma_px_(sigma_mm / op.geometry().pixel_pitch) {}
  bool active() const { return sigma_px_ > 0; }
  void apply(std::span<float> image) {
    cv::Mat in(height_, width_, CV_32F, image.data());
    cv::GaussianBlur(in, scratch_, cv::Size(0, 0), sigma_px_, sigma_px_, cv::BORDER_CONSTANT);
    scratch_.copyTo(in);
  }

 private:
  int width_, height_;
  double sigma_px_;
  cv::Mat scratch_;
};

double sum(std::span<const float> a) {
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

// The image MART sees, in `out`: pixels at or below the noise threshold become 0.
void threshold_image(const ImageF& image, float threshold, BigBuffer<float>& out) {
  fit(out, image.pixels.size());
  for_pixels(out.size(), [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) out[i] = image.pixels[i] > threshold ? image.pixels[i] : 0.f;
  });
}

bool in_region(const Grid3& g, const std::optional<RegionMm>& region, int x, int y, int z) {
  if (!region) return true;
  const int idx[3] = {x, y, z};
  for (int a = 0; a < 3; ++a) {
    const double c = g.coordinate_mm(a, idx[a]);
    if (c < region->min_mm[a] || c > region->max_mm[a]) return false;
  }
  return true;
}

// select_active's largest arrays, kept across frames.
struct SelectScratch {
  std::vector<std::uint64_t> dark;                    // dark pixels as bits, per sensor column
  std::vector<std::vector<std::uint32_t>> per_slice;  // each slice's active voxels
};

// Voxels MART can change: seen by some pixel, inside the region, and seen by no dark pixel (a
// dark pixel's ratio is 0, so eq 9 zeroes every voxel it sees and they stay zero). "Seen" here:
// a pixel where both the voxel's column weight and its row weight exceed the cutoff's fraction
// of their largest value.
//
// The test is separable: voxel (x, y) of slice z is dark when some row r among y's strong rows
// holds a dark pixel in one of x's strong columns. So the dark pixels are kept column by column
// as bits over the sensor rows; per voxel column x the OR of its strong columns' bits gives the
// rows where x meets a dark pixel, per voxel row y its strong rows are bits too, and each voxel
// costs one AND over the words of y's strong rows.
std::vector<std::uint32_t> select_active(const WeightingOperator& op, std::span<const float> image,
                                         const MartSettings& settings, SelectScratch& scratch, SkipReport& report) {
  const Grid3& g = op.grid();
  const int width = op.image_width(), height = op.image_height();
  const std::size_t words = std::size_t(height + 63) / 64;  // per sensor column
  std::vector<std::uint64_t>& dark = scratch.dark;  // [column][row word]
  dark.assign(std::size_t(width) * words, 0);
  const float* white = op.white().pixels.data();
  report.pixels = op.pixel_count();
  // Each group of 64 sensor rows owns its word of every column.
  std::vector<std::size_t> dark_in_group(words, 0);
  tbb::parallel_for(std::size_t(0), words, [&](std::size_t w) {
    std::size_t count = 0;
    const int r1 = std::min(height, int(64 * w) + 64);
    for (int r = int(64 * w); r < r1; ++r) {
      const std::uint64_t bit = std::uint64_t(1) << (r & 63);
      const std::size_t row = std::size_t(r) * std::size_t(width);
      for (int c = 0; c < width; ++c) {
        if (white[row + std::size_t(c)] > 0.f && image[row + std::size_t(c)] == 0.f) {
          dark[std::size_t(c) * words + w] |= bit;
          ++count;
        }
      }
    }
    dark_in_group[w] = count;
  });
  for (std::size_t count : dark_in_group) report.dark_pixels += count;

  const int nx = g.shape[0], ny = g.shape[1], nz = g.shape[2];
  const float cutoff = float(settings.dark_weight_cutoff);
  report.voxels = g.count();
  report.slices = nz;
  std::vector<std::vector<std::uint32_t>>& per_slice = scratch.per_slice;
  per_slice.resize(std::size_t(nz));
  std::vector<std::array<std::size_t, 3>> counts(std::size_t(nz), {0, 0, 0});  // unseen, outside, dark
  auto peak_of = [](const AxisWeights& a) {
    float peak = 0.f;
    for (const Segment& s : a.segments) {
      for (int k = 0; k < s.length; ++k) peak = std::max(peak, a.table[s.offset + std::size_t(k)]);
    }
    return peak;
  };
  tbb::parallel_for(0, nz, [&](int z) {
    // Per voxel column x: the sensor rows where one of its strong columns is dark.
    std::vector<std::uint64_t> dark_rows(std::size_t(nx) * words, 0);
    for (int x = 0; x < nx; ++x) {
      const AxisWeights ax = op.x_weights(z, x);
      const float cut = cutoff * peak_of(ax);
      std::uint64_t* rows = dark_rows.data() + std::size_t(x) * words;
      for (const Segment& s : ax.segments) {
        for (int c = 0; c < s.length; ++c) {
          if (!(ax.table[s.offset + std::size_t(c)] > cut)) continue;
          const std::uint64_t* column = dark.data() + std::size_t(s.first + c) * words;
          for (std::size_t w = 0; w < words; ++w) rows[w] |= column[w];
        }
      }
    }
    auto& out = per_slice[std::size_t(z)];
    out.clear();
    out.reserve(std::size_t(nx) * std::size_t(ny));
    auto& cnt = counts[std::size_t(z)];
    std::vector<std::uint64_t> strong(words, 0);  // voxel row y's strong rows
    for (int y = 0; y < ny; ++y) {
      const AxisWeights ay = op.y_weights(z, y);
      const float row_cut = cutoff * peak_of(ay);
      std::size_t w0 = words, w1 = 0;  // the words holding strong rows: [w0, w1)
      for (const Segment& s : ay.segments) {
        for (int r = 0; r < s.length; ++r) {
          if (!(ay.table[s.offset + std::size_t(r)] > row_cut)) continue;
          const std::size_t w = std::size_t(s.first + r) >> 6;
          strong[w] |= std::uint64_t(1) << ((s.first + r) & 63);
          w0 = std::min(w0, w);
          w1 = std::max(w1, w + 1);
        }
      }
      for (int x = 0; x < nx; ++x) {
        const std::size_t v = g.index(x, y, z);
        if (!(op.normaliser(v) > 0.f)) {
          ++cnt[0];
          continue;
        }
        if (!in_region(g, settings.region, x, y, z)) {
          ++cnt[1];
          continue;
        }
        const std::uint64_t* rows = dark_rows.data() + std::size_t(x) * words;
        std::uint64_t hit = 0;
        for (std::size_t w = w0; w < w1; ++w) hit |= rows[w] & strong[w];
        if (hit) {
          ++cnt[2];
        } else {
          out.push_back(std::uint32_t(v));
        }
      }
      for (std::size_t w = w0; w < w1; ++w) strong[w] = 0;
    }
  });
  // Slices one after another, copied in parallel.
  std::vector<std::size_t> offset(std::size_t(nz) + 1, 0);
  for (int z = 0; z < nz; ++z) {
    const auto& s = per_slice[std::size_t(z)];
    if (s.empty()) ++report.slices_empty;
    offset[std::size_t(z) + 1] = offset[std::size_t(z)] + s.size();
    report.voxels_unseen += counts[std::size_t(z)][0];
    report.voxels_outside_region += counts[std::size_t(z)][1];
    report.voxels_dark += counts[std::size_t(z)][2];
  }
  std::vector<std::uint32_t> active(offset.back());
  tbb::parallel_for(0, nz, [&](int z) {
    const auto& s = per_slice[std::size_t(z)];
    std::copy(s.begin(), s.end(), active.begin() + std::ptrdiff_t(offset[std::size_t(z)]));
  });
  report.voxels_active = active.size();
  return active;
}

// ln I for the pixels MART uses (0 elsewhere: those pixels see no active voxel).
float log_pixel(float v) { return v > 0.f ? std::log(std::max(v, kTiny)) : 0.f; }

std::vector<float> log_image(std::span<const float> image) {
  std::vector<float> out(image.size());
  for (std::size_t i = 0; i < image.size(); ++i) out[i] = log_pixel(image[i]);
  return out;
}

float bounded_exp(float x) { return std::exp(std::clamp(x, -kMaxLog, kMaxLog)); }

float clean(float v) { return v < kTiny ? 0.f : std::min(v, kHuge); }

}  // namespace

void apply_sensor_blur(const WeightingOperator& op, double sigma_mm, std::span<float> image) {
  check_sensor_blur_sigma(sigma_mm, "apply_sensor_blur");
  if (image.size() != op.pixel_count()) throw InputError("sensor blur: the image is not the operator's sensor");
  SensorBlur blur(op, sigma_mm);
  if (blur.active()) blur.apply(image);
}

void validate_image(const ImageF& image, const WeightingOperator& op, const char* source) {
  if (image.width != op.image_width() || image.height != op.image_height()) {
    throw InputError(std::string(source) + ": image is " + std::to_string(image.width) + " x " +
                     std::to_string(image.height) + " px, the camera's sensor is " +
                     std::to_string(op.image_width()) + " x " + std::to_string(op.image_height()));
  }
  // Checked in parallel; only an image that fails is scanned again in order to name its first
  // bad pixel.
  std::atomic<bool> bad{false};
  for_pixels(image.pixels.size(), [&](std::size_t i0, std::size_t i1) {
    bool chunk_bad = false;
    for (std::size_t i = i0; i < i1; ++i) {
      const float v = image.pixels[i];
      chunk_bad |= !(v >= 0.f && v <= kHuge);  // NaN fails both
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
    if (v > kHuge) {
      throw InputError(std::string(source) + ": pixel value " + std::to_string(v) + " exceeds " +
                       std::to_string(kHuge) + "; scale the image down");
    }
  }
}

namespace detail {
// What a MartWorkspace holds. Every reconstruction sizes and writes each buffer before reading it.
struct MartBuffers {
  std::atomic<bool> busy{false};
  // Per sensor pixel: the thresholded image, ln I, W E and white · ln(I / W E).
  BigBuffer<float> data, log_data, projection, ratio;
  // Per active voxel: E, the back-projected update, MLOS's weight, and the momentum's three.
  BigBuffer<float> e, update, weight, last, log_last, momentum;
  ActiveSet::Workspace kernels;  // reused by every pass
  SelectScratch select;
};
}  // namespace detail

MartWorkspace::MartWorkspace() : buffers_(std::make_unique<detail::MartBuffers>()) {}
MartWorkspace::~MartWorkspace() = default;
MartWorkspace::MartWorkspace(MartWorkspace&&) noexcept = default;
MartWorkspace& MartWorkspace::operator=(MartWorkspace&&) noexcept = default;

std::size_t MartWorkspace::bytes() const {
  if (!buffers_) return 0;  // moved from
  const detail::MartBuffers& b = *buffers_;
  std::size_t total = 0;
  for (const auto* v : {&b.data, &b.log_data, &b.projection, &b.ratio, &b.e, &b.update, &b.weight, &b.last, &b.log_last, &b.momentum}) {
    total += v->capacity() * sizeof(float);
  }
  total += b.kernels.scaled.capacity() * sizeof(float) + b.kernels.sums.capacity() * sizeof(double);
  total += (b.kernels.band_lanes.capacity() + b.kernels.image_lanes.capacity()) * sizeof(float);
  total += b.select.dark.capacity() * sizeof(std::uint64_t);
  for (const auto& slice : b.select.per_slice) total += slice.capacity() * sizeof(std::uint32_t);
  return total;
}

MartResult reconstruct(const WeightingOperator& op, const ImageF& image, const MartSettings& settings,
                       const std::function<void(const IterationReport&)>& progress) {
  MartWorkspace workspace;
  return reconstruct(op, image, settings, workspace, progress);
}

MartResult reconstruct(const WeightingOperator& op, const ImageF& image, const MartSettings& settings,
                       MartWorkspace& workspace, const std::function<void(const IterationReport&)>& progress) {
  if (!workspace.buffers_) throw InputError("MART: the workspace was moved from; use the one it was moved to");
  detail::MartBuffers& buffers = *workspace.buffers_;
  if (buffers.busy.exchange(true)) {
    throw InputError("MART: the workspace is in use by another reconstruction; give each concurrent "
                     "reconstruction its own");
  }
  struct Release {
    std::atomic<bool>& busy;
    ~Release() { busy.store(false); }
  } release{buffers.busy};
  validate_settings(settings);
  validate_image(image, op, "image");
  if (settings.method != MartMethod::smart) {
    throw InputError("MART: the matrix-free reconstruction runs the simultaneous form; the row-action "
                     "form needs the explicit matrix (reconstruct_row_action)");
  }
  const auto t_setup = std::chrono::steady_clock::now();
  MartResult result;
  result.volume = Volume(op.grid(), 0.f);
  BigBuffer<float>& data = buffers.data;
  threshold_image(image, settings.noise_threshold, data);
  std::vector<std::uint32_t> selected = select_active(op, data, settings, buffers.select, result.skipped);
  result.select_seconds = seconds_since(t_setup);
  const auto t_active = std::chrono::steady_clock::now();
  const ActiveSet active(op, std::move(selected));
  result.active_set_seconds = seconds_since(t_active);
  const auto t_start = std::chrono::steady_clock::now();
  const std::size_t n = active.size();
  ActiveSet::Workspace& workspace_kernels = buffers.kernels;
  // Per active voxel; BigBuffers (huge pages: 26 MB each on the paper case would otherwise take
  // 6 500 page faults apiece). `update` is written in full by every back-projection.
  BigBuffer<float>& e = buffers.e;
  BigBuffer<float>& update = buffers.update;
  e.assign(n, 1.f);
  fit(update, n);
  // Written in full by every pass before being read. ratio: white · ln(I / W E).
  BigBuffer<float>& projection = buffers.projection;
  BigBuffer<float>& ratio = buffers.ratio;
  fit(projection, op.pixel_count());
  fit(ratio, op.pixel_count());
  const float* white = op.white().pixels.data();
  auto for_voxels = [n](auto&& f) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 12), [&](const tbb::blocked_range<std::size_t>& r) {
      for (std::size_t m = r.begin(); m != r.end(); ++m) f(m);
    });
  };

  // What a dark pixel recorded at most: the noise threshold, or half the faintest lit pixel.
  float dark_floor = settings.noise_threshold;
  if (!(dark_floor > 0.f)) {
    // A minimum: the same whatever the order.
    const float faintest = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, data.size(), 1 << 14), kHuge,
        [&](const tbb::blocked_range<std::size_t>& r, float m) {
          for (std::size_t i = r.begin(); i != r.end(); ++i) {
            if (data[i] > 0.f) m = std::min(m, data[i]);
          }
          return m;
        },
        [](float a, float b) { return std::min(a, b); });
    dark_floor = 0.5f * faintest;
  }
  if (settings.start == MartStart::mlos && n > 0) {
    // The weighted geometric mean of the lit pixels a voxel sees (dark ones below the cutoff
    // carry no ln I), renormalised over those pixels.
    // The lit mask and ln I, each times the white image, in the ratio and projection buffers
    // (not yet in use), back-projected in one walk.
    BigBuffer<float>& weight = buffers.weight;  // written in full by the back-projection
    fit(weight, n);
    for_pixels(data.size(), [&](std::size_t i0, std::size_t i1) {
      for (std::size_t i = i0; i < i1; ++i) {
        ratio[i] = (data[i] > 0.f ? 1.f : 0.f) * white[i];
        projection[i] = log_pixel(data[i]) * white[i];
      }
    });
    active.back_project_whitened(op, ratio, weight, projection, update, &workspace_kernels);
    for_voxels([&](std::size_t m) { e[m] = weight[m] > 0.f ? clean(bounded_exp(update[m] / weight[m])) : 0.f; });
    // Scale to the image's total light so the first ratios are near 1. The projection's total
    // is Σ_j E_j (eq 13 makes each voxel's weights sum to 1 over the sensor), so no projection
    // is needed; the two totals differ by the projection's float rounding only (~1e-10 relative
    // on the paper case: the float scale and the volume's bits come out the same there,
    // docs/benchmarks.md).
    const double total = sum(e);
    if (total > 0) {
      const float scale = float(sum(data) / total);
      for_voxels([&](std::size_t m) { e[m] = clean(e[m] * scale); });
    }
  }
  result.start_seconds = seconds_since(t_start);
  result.setup_seconds = seconds_since(t_setup);

  // ln I and ln floor once, not per iteration.
  BigBuffer<float>& log_data = buffers.log_data;
  fit(log_data, data.size());
  for_pixels(data.size(), [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) log_data[i] = data[i] > 0.f ? std::log(data[i]) : 0.f;
  });
  const float log_floor = std::log(dark_floor);
  // Work on each band of the projection as soon as it is finished, while its pixels are in cache:
  // the residual's two sums (kept per band and added in band order, so the same at any thread
  // count) and the log-ratios the update back-projects.
  std::vector<std::array<double, 2>> band_sums(std::size_t(active.band_count()));
  auto residual_band = [&](int band, std::size_t i0, std::size_t i1) {
    double num = 0, den = 0;
    for (std::size_t i = i0; i < i1; ++i) {
      const double diff = double(data[i]) - double(projection[i]);
      num += diff * diff;
      den += double(data[i]) * double(data[i]);
    }
    band_sums[std::size_t(band)] = {num, den};
  };
  auto residual = [&] {  // ||I - W E|| / ||I||
    double num = 0, den = 0;
    for (const auto& b : band_sums) {
      num += b[0];
      den += b[1];
    }
    return den > 0 ? std::sqrt(num / den) : 0.0;
  };
  // The log-ratio of each pixel MART uses, times `scale` (the white image, or 1 where the sensor
  // blur is applied before whitening).
  auto ratio_band = [&](std::size_t i0, std::size_t i1, const float* scale) {
    for (std::size_t i = i0; i < i1; ++i) {
      const float p = projection[i], d = data[i], k = scale ? scale[i] : 1.f;
      if (white[i] == 0.f) {
        ratio[i] = 0.f;  // between microlens images: no voxel sees the pixel
      } else if (d > 0.f) {
        ratio[i] = p > 0.f ? k * std::clamp(log_data[i] - std::log(p), -kMaxLog, kMaxLog) : 0.f;
      } else {
        // A dark pixel the voxel sees only faintly: it recorded at most the floor, so it pulls
        // the voxels that claim more light there down (never up).
        ratio[i] = p > dark_floor ? k * std::max(log_floor - std::log(p), -kMaxLog) : 0.f;
      }
    }
  };
  // Projection W E (B W E with the sensor blur), the residual's sums and, if `with_ratio`, the
  // whitened log-ratios the update back-projects. Without blur, each band is finished while its
  // pixels are in cache; with it, the whole projection must exist before the blur.
  SensorBlur blur(op, settings.sensor_blur_sigma_mm);
  auto project_and_compare = [&](bool with_ratio) {
    if (!blur.active()) {
      active.project(op, e, projection, &workspace_kernels, [&](int band, std::size_t i0, std::size_t i1) {
        residual_band(band, i0, i1);
        if (with_ratio) ratio_band(i0, i1, white);
      });
      return;
    }
    active.project(op, e, projection, &workspace_kernels);
    blur.apply(projection);
    // The residual's sums in fixed pixel bands (the projection's own bands no longer apply).
    const std::size_t bands = band_sums.size(), per_band = (data.size() + bands - 1) / bands;
    tbb::parallel_for(std::size_t(0), bands, [&](std::size_t b) {
      residual_band(int(b), std::min(data.size(), b * per_band), std::min(data.size(), (b + 1) * per_band));
    });
    if (!with_ratio) return;
    for_pixels(data.size(), [&](std::size_t i0, std::size_t i1) { ratio_band(i0, i1, nullptr); });
    blur.apply(ratio);
    for_pixels(data.size(), [&](std::size_t i0, std::size_t i1) {
      for (std::size_t i = i0; i < i1; ++i) ratio[i] *= white[i];
    });
  };
  // Nesterov's momentum on ln E (settings.accelerate): each iteration starts from the
  // extrapolated y = x_k (x_k / x_(k-1))^beta_k with FISTA's beta_k = (k - 1) / (k + 2), and k
  // restarts at 1 when an iteration's step opposes the momentum (O'Donoghue and Candes's gradient
  // restart). `last` holds x_(k-1), then x_k; `log_last` its ln (kept, so each iteration takes one
  // log per voxel, not two); `momentum` ln x_k - ln x_(k-1) (0 where either is 0).
  BigBuffer<float>& last = buffers.last;
  BigBuffer<float>& log_last = buffers.log_last;
  BigBuffer<float>& momentum = buffers.momentum;
  if (settings.accelerate) {
    last.assign(e.begin(), e.end());
    log_last.resize(n);  // written in full here
    for_voxels([&](std::size_t m) { log_last[m] = last[m] > 0.f ? std::log(last[m]) : 0.f; });
    momentum.assign(n, 0.f);
  }
  int momentum_step = 1;
  double previous = -1;
  for (int it = 1; it <= settings.iterations && n > 0; ++it) {
    const auto t_it = std::chrono::steady_clock::now();
    const float beta = float(momentum_step - 1) / float(momentum_step + 2);
    if (settings.accelerate) {
      for_voxels([&](std::size_t m) {
        const float log_e = e[m] > 0.f ? std::log(e[m]) : 0.f;
        momentum[m] = e[m] > 0.f && last[m] > 0.f ? log_e - log_last[m] : 0.f;
        last[m] = e[m];
        log_last[m] = log_e;
        e[m] = clean(e[m] * bounded_exp(beta * momentum[m]));
      });
    }
    project_and_compare(true);
    const double r = residual();
    if (previous >= 0 && settings.convergence > 0 && std::abs(previous - r) <= settings.convergence * previous) {
      result.converged = true;
      if (settings.accelerate) e = last;  // x_k, not the extrapolated point
      break;
    }
    previous = r;
    active.back_project_whitened(op, ratio, update, &workspace_kernels);
    const float mu = float(settings.mu);
    for_voxels([&](std::size_t m) { e[m] = clean(e[m] * bounded_exp(mu * update[m])); });
    if (settings.accelerate) {
      // Does this step (ln x_(k+1) - ln y = mu * update) go along the momentum? Summed in fixed
      // chunks, so the restart is the same at any thread count.
      const double along = tbb::parallel_deterministic_reduce(
          tbb::blocked_range<std::size_t>(0, n, 1 << 14), 0.0,
          [&](const tbb::blocked_range<std::size_t>& range, double acc) {
            for (std::size_t m = range.begin(); m != range.end(); ++m) acc += double(update[m]) * double(momentum[m]);
            return acc;
          },
          std::plus<double>());
      momentum_step = along < 0 ? 1 : momentum_step + 1;
    }
    IterationReport rep{it, r, seconds_since(t_it)};
    result.iterations.push_back(rep);
    if (progress) progress(rep);
  }
  if (settings.final_residual) {
    if (n > 0) {
      project_and_compare(false);
      result.final_residual = residual();
    } else {
      result.final_residual = sum(data) > 0 ? 1.0 : 0.0;  // nothing projected: ||I - 0|| / ||I||
    }
  }
  const std::vector<std::uint32_t>& voxels = active.voxels();
  for_voxels([&](std::size_t m) { result.volume.data[voxels[m]] = e[m]; });  // distinct voxels
  return result;
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
  threshold_image(image, settings.noise_threshold, data);
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
        if (!in_region(g, settings.region, x, y, z) || !(op.normaliser(j) > 0.f)) e[j] = 0.f;
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
  Volume out(g, 0.f);
  out.data = std::move(e);
  return out;
}

}  // namespace plenopiv::recon
