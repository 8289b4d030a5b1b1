// Ray-traced plenoptic images (paper sec 4, fig 10): particles, calibration and white targets.
#include "core/sim/render.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <thread>

#include "core/base/errors.hpp"
#include "core/base/memory.hpp"

namespace plenopiv::sim {
namespace {

// splitmix64 (Steele, Lea & Flood 2014): tiny, fast, and good enough for ray sampling; one
// stream per emitter, started from a hash of (seed, emitter index).
std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t state) : state_(state) {}
  std::uint64_t next() { return mix64(state_ += 0x9e3779b97f4a7c15ULL); }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }                  // [0, 1)
  double symmetric() { return double(std::int64_t(next()) >> 11) * 0x1.0p-52; }  // [-1, 1)
  // Two values in [-1, 1) from one draw, 32 bits each (3e-9 of the aperture radius: plenty).
  void symmetric_pair(double& a, double& b) {
    const std::uint64_t bits = next();
    a = double(std::int32_t(std::uint32_t(bits))) * 0x1.0p-31;
    b = double(std::int32_t(std::uint32_t(bits >> 32))) * 0x1.0p-31;
  }
  // Two independent standard normals (Marsaglia's polar method: one log, one sqrt, no sin/cos).
  void normal_pair(double& a, double& b) {
    double u, v, s;
    do {
      u = symmetric();
      v = symmetric();
      s = u * u + v * v;
    } while (s >= 1.0 || s == 0.0);
    const double f = std::sqrt(-2.0 * std::log(s) / s);
    a = u * f;
    b = v * f;
  }

 private:
  std::uint64_t state_;
};

std::uint64_t stream_seed(std::uint64_t seed, std::uint64_t index) {
  return mix64(mix64(seed + 0x632be59bd9b4e019ULL) ^ (index * 0x9e3779b97f4a7c15ULL + 1));
}

// Standard normal quantiles at the 2^12 cell midpoints (k + 0.5) / 2^12: one 64-bit draw gives
// four normal samples by table look-up from a 16 KB table that stays in L1 (a 2^16-entry double
// table, 512 KB, misses the cache on every ray). The tails are cut at 3.5 sigma and the variance
// is 0.997; for the diffraction jitter (sigma 5.2 um against a 7.4 um pixel) neither is visible.
class NormalTable {
 public:
  static const NormalTable& get() {
    static const NormalTable table;
    return table;
  }
  // Four normals from one draw.
  void four(std::uint64_t bits, double out[4]) const {
    for (int k = 0; k < 4; ++k) out[k] = q_[(bits >> (16 * k + 4)) & 0xfff];
  }

 private:
  NormalTable() : q_(1 << 12) {
    // Bisection on Phi(x) = erfc(-x / sqrt 2) / 2: cannot diverge in the tails; the upper half
    // mirrors the lower.
    const std::size_t n = q_.size();
    for (std::size_t k = 0; k < n / 2; ++k) {
      const double p = (double(k) + 0.5) / double(n);
      double lo = -10, hi = 0;
      for (int it = 0; it < 56; ++it) {
        const double mid = 0.5 * (lo + hi);
        (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
      }
      q_[k] = float(0.5 * (lo + hi));
      q_[n - 1 - k] = -q_[k];
    }
  }
  std::vector<float> q_;
};

// A light source: a point (w = 0) or a uniformly lit rectangle of w_x by w_y centred at (x, y).
struct Emitter {
  double x, y, z, w_x, w_y;
  double light = 1.0;  // the emitter's rays: the render's rays per emitter times this
};

// Everything a ray needs, resolved once per render.
class Tracer {
 public:
  Tracer(const optics::CameraModel& camera, const optics::MicrolensArray& array, double aperture_diameter_mm,
         double overfill, double sigma_mm, const VignettingStop& stop, const std::vector<float>& transmission,
         std::uint32_t* counts)
      : s_o_(camera.object_distance_mm()),
        s_i_(camera.image_distance_mm()),
        inv_f_m_(1.0 / camera.main_lens().focal_length_mm),
        f_l_(camera.microlens().focal_length_mm),
        inv_f_l_(1.0 / f_l_),
        aperture_r2_(0.25 * aperture_diameter_mm * aperture_diameter_mm),
        sample_r_(0.5 * aperture_diameter_mm * overfill),
        overfilled_(overfill > 1.0),
        sigma_(sigma_mm),
        stop_distance_(stop.distance_mm),
        stop_r2_(0.25 * stop.diameter_mm * stop.diameter_mm),
        vignetting_(stop.diameter_mm > 0),
        transmission_(transmission.empty() ? nullptr : transmission.data()),
        lattice_(array.lattice),
        cos_(std::cos(array.lattice.rotation_rad)),
        sin_(std::sin(array.lattice.rotation_rad)),
        inv_pitch_x_(1.0 / array.lattice.pitch_x_mm),
        inv_pitch_y_(1.0 / array.lattice.pitch_y_mm),
        centres_(array.centres_mm.data()),
        width_(camera.sensor().width_px),
        height_(camera.sensor().height_px),
        inv_pp_(1.0 / camera.sensor().pixel_pitch_mm),
        // Pixel k covers [k - 0.5, k + 0.5) in optics::sensor_mm_to_column's coordinates: the
        // landing column plus 0.5, truncated, is the pixel.
        column_origin_(camera.sensor().optical_axis_px ? (*camera.sensor().optical_axis_px)[0] + 0.5 : 0.5 * width_),
        row_origin_(camera.sensor().optical_axis_px ? (*camera.sensor().optical_axis_px)[1] + 0.5 : 0.5 * height_),
        counts_(counts),
        normals_(NormalTable::get()) {
    // The nearest lattice point is the struck lens only for a rect lattice whose lenses sit
    // exactly on it; otherwise the 3x3 lattice neighbourhood is searched for the nearest centre.
    exact_rect_ = lattice_.layout == optics::LensletLayout::rect;
    for (int j = 0; j < lattice_.count_y && exact_rect_; ++j) {
      for (int i = 0; i < lattice_.count_x; ++i) {
        if (lattice_.position(i, j) != array.centre(i, j)) {
          exact_rect_ = false;
          break;
        }
      }
    }
  }

  void trace(const Emitter& e, std::size_t rays, SplitMix64& rng, RayCounts& c) const {
    // Ray-transfer matrices of fig 10, per axis on (position, slope):
    //  1 free space d = s_o + z, 2 thin lens f_m, 3 free space s_i,
    //  4 microlens at centre c (affine: slope -= (x - c) / f_l), 5 free space f_l.
    // The ray is fixed by its source point and aperture point a, so 1 gives slope (a - x)/d at
    // the lens; 2 and 3 are applied in closed form below.
    const double inv_d = 1.0 / (s_o_ + e.z);
    const bool extended = e.w_x > 0 || e.w_y > 0;
    for (std::size_t r = 0; r < rays; ++r) {
      double ax, ay;
      do {
        rng.symmetric_pair(ax, ay);
      } while (ax * ax + ay * ay >= 1.0);
      ax *= sample_r_;
      ay *= sample_r_;
      if (overfilled_ && ax * ax + ay * ay > aperture_r2_) {
        ++c.outside_aperture;
        continue;
      }
      double xo = e.x, yo = e.y;
      if (extended) {
        xo += e.w_x * (rng.uniform() - 0.5);
        yo += e.w_y * (rng.uniform() - 0.5);
      }
      // 1 + 2: slope after the main lens; 3: position on the microlens plane.
      const double tx = (ax - xo) * inv_d - ax * inv_f_m_;
      const double ty = (ay - yo) * inv_d - ay * inv_f_m_;
      if (vignetting_) {
        const double vx = ax + stop_distance_ * tx, vy = ay + stop_distance_ * ty;
        if (vx * vx + vy * vy > stop_r2_) {
          ++c.outside_aperture;
          continue;
        }
      }
      double xm = ax + s_i_ * tx;
      double ym = ay + s_i_ * ty;
      double jitter[4];
      if (sigma_ > 0) {
        normals_.four(rng.next(), jitter);
        xm += sigma_ * jitter[0];
        ym += sigma_ * jitter[1];
      }
      double cx = 0, cy = 0;
      if (!strike(xm, ym, cx, cy)) {
        ++c.missed_array;
        continue;
      }
      // 4 + 5: the microlens turns the slope about its own centre, then f_l to the sensor.
      double xs = xm + f_l_ * (tx - (xm - cx) * inv_f_l_);
      double ys = ym + f_l_ * (ty - (ym - cy) * inv_f_l_);
      if (sigma_ > 0) {
        xs += sigma_ * jitter[2];
        ys += sigma_ * jitter[3];
      }
      // The range check comes first, so truncation is floor.
      const double col = xs * inv_pp_ + column_origin_;
      const double row = ys * inv_pp_ + row_origin_;
      if (!(col >= 0 && col < width_ && row >= 0 && row < height_)) {
        ++c.outside_sensor;
        continue;
      }
      const std::size_t pixel = std::size_t(row) * width_ + std::size_t(col);
      if (transmission_ && transmission_[pixel] < 1.0f && rng.uniform() >= transmission_[pixel]) {
        ++c.absorbed;
        continue;
      }
      std::atomic_ref<std::uint32_t>(counts_[pixel]).fetch_add(1, std::memory_order_relaxed);
      ++c.landed;
    }
    c.emitted += rays;
  }

 private:
  // The lens whose cell (nearest centre) holds (x, y) on the microlens plane; false beside
  // the array.
  bool strike(double x, double y, double& cx, double& cy) const {
    const double dx = x - lattice_.offset_x_mm, dy = y - lattice_.offset_y_mm;
    const double a = cos_ * dx - sin_ * dy;  // inverse of Lattice::position's rotation
    const double b = sin_ * dx + cos_ * dy;
    const int nx = lattice_.count_x, ny = lattice_.count_y;
    // Nearest lattice row and column; range checks first, so truncation is floor.
    const double fj = b * inv_pitch_y_ + 0.5 * ny;
    if (!(fj >= 0 && fj < ny)) return false;
    const int j0 = int(fj);
    double fi = a * inv_pitch_x_ + 0.5 * nx;
    if (lattice_.layout == optics::LensletLayout::hex) fi -= (j0 & 1) ? 0.25 : -0.25;
    if (!(fi >= 0 && fi < nx)) return false;
    const int i0 = int(fi);
    if (exact_rect_) {
      const auto& p = centres_[std::size_t(j0) * nx + i0];
      cx = p[0];
      cy = p[1];
      return true;
    }
    double best = std::numeric_limits<double>::infinity();
    for (int j = std::max(0, j0 - 1); j <= std::min(ny - 1, j0 + 1); ++j) {
      for (int i = std::max(0, i0 - 1); i <= std::min(nx - 1, i0 + 1); ++i) {
        const auto& p = centres_[std::size_t(j) * nx + i];
        const double d2 = (p[0] - x) * (p[0] - x) + (p[1] - y) * (p[1] - y);
        if (d2 < best) {
          best = d2;
          cx = p[0];
          cy = p[1];
        }
      }
    }
    return true;
  }

  double s_o_, s_i_, inv_f_m_, f_l_, inv_f_l_;
  double aperture_r2_, sample_r_;
  bool overfilled_;
  double sigma_;
  double stop_distance_, stop_r2_;
  bool vignetting_;
  const float* transmission_;
  optics::Lattice lattice_;
  double cos_, sin_, inv_pitch_x_, inv_pitch_y_;
  const std::array<double, 2>* centres_;
  bool exact_rect_ = true;
  int width_, height_;
  double inv_pp_;
  double column_origin_, row_origin_;
  std::uint32_t* counts_;
  const NormalTable& normals_;
};

void check_finite_nonnegative(double v, const char* name) {
  if (!std::isfinite(v) || v < 0) {
    throw InputError(std::string("render options: ") + name + ": must be a finite number >= 0, got " +
                     std::to_string(v));
  }
}

void check_sensor(const SensorModel& s) {
  check_finite_nonnegative(s.electrons_per_ray, "sensor.electrons_per_ray");
  check_finite_nonnegative(s.read_noise_electrons, "sensor.read_noise_electrons");
  check_finite_nonnegative(s.dark_offset_dn, "sensor.dark_offset_dn");
  check_finite_nonnegative(s.right_half_offset_dn, "sensor.right_half_offset_dn");
  if (!(s.gain_dn_per_electron > 0) || !std::isfinite(s.gain_dn_per_electron)) {
    throw InputError("render options: sensor.gain_dn_per_electron: must be > 0");
  }
  if (s.bit_depth < 1 || s.bit_depth > 16) {
    throw InputError("render options: sensor.bit_depth: must be 1..16, got " + std::to_string(s.bit_depth));
  }
  for (std::size_t k = 0; k < s.dust.size(); ++k) {
    const DustSpot& d = s.dust[k];
    if (!std::isfinite(d.column) || !std::isfinite(d.row) || !(d.radius_px >= 0) || !(d.edge_px >= 0) ||
        !(d.opacity >= 0 && d.opacity <= 1) || !std::isfinite(d.radius_px + d.edge_px)) {
      throw InputError("render options: sensor.dust[" + std::to_string(k) +
                       "]: needs a finite position, radius and edge >= 0, opacity 0..1");
    }
  }
}

void check_vignetting(const VignettingStop& v) {
  if (!std::isfinite(v.distance_mm) || !std::isfinite(v.diameter_mm) || v.diameter_mm < 0) {
    throw InputError("render options: vignetting: needs a finite distance and a diameter >= 0 mm");
  }
}

// Per pixel, the share of light the dust shadows pass (at the pixel centre); empty without dust.
std::vector<float> dust_transmission(const SensorModel& sensor, int width, int height) {
  std::vector<float> t;
  if (sensor.dust.empty()) return t;
  t.assign(std::size_t(width) * height, 1.0f);
  for (const DustSpot& d : sensor.dust) {
    const double reach = d.radius_px + 0.5 * d.edge_px;
    const int x0 = std::max(0, int(std::floor(d.column - reach))),
              x1 = std::min(width - 1, int(std::ceil(d.column + reach)));
    const int y0 = std::max(0, int(std::floor(d.row - reach))),
              y1 = std::min(height - 1, int(std::ceil(d.row + reach)));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const double r = std::hypot(x - d.column, y - d.row);
        const double core =
            d.edge_px > 0 ? std::clamp((reach - r) / d.edge_px, 0.0, 1.0) : (r <= d.radius_px ? 1.0 : 0.0);
        t[std::size_t(y) * width + x] *= float(1.0 - d.opacity * core);
      }
    }
  }
  return t;
}

void check_array(const optics::MicrolensArray& array) {
  const optics::Lattice& l = array.lattice;
  if (l.count_x <= 0 || l.count_y <= 0 || !(l.pitch_x_mm > 0) || !(l.pitch_y_mm > 0) ||
      array.centres_mm.size() != std::size_t(l.count())) {
    throw InputError("render: the microlens array is empty or its centres do not match its lattice");
  }
}

// Traces every emitter in parallel; counts are integers, so any order gives the same sums.
RenderResult trace_all(const optics::CameraModel& camera, const optics::MicrolensArray& array,
                       std::span<const Emitter> emitters, std::size_t rays_per_emitter, double aperture_diameter_mm,
                       double overfill, double sigma_mm, const VignettingStop& vignetting, const SensorModel& sensor,
                       const std::function<void(double)>& progress, std::uint64_t seed) {
  check_array(array);
  check_sensor(sensor);
  check_vignetting(vignetting);
  check_finite_nonnegative(sigma_mm, "diffraction_sigma_mm");
  if (!(aperture_diameter_mm > 0) || !std::isfinite(aperture_diameter_mm)) {
    throw InputError("render options: aperture diameter must be > 0");
  }
  if (!(overfill >= 1.0) || !std::isfinite(overfill)) {
    throw InputError("render options: aperture_overfill: must be >= 1, got " + std::to_string(overfill));
  }
  const int w = camera.sensor().width_px, h = camera.sensor().height_px;
  // The counters, the ray image, the sensor image and (with dust) its transmission are held at once.
  const std::size_t pixels = checked_count(
      w, h, 1,
      sizeof(std::uint32_t) + sizeof(float) + sizeof(std::uint16_t) + (sensor.dust.empty() ? 0 : sizeof(float)),
      "rendering a " + std::to_string(w) + " x " + std::to_string(h) + " px frame");
  std::vector<std::uint32_t> counts(pixels, 0);
  const std::vector<float> transmission = dust_transmission(sensor, w, h);
  const Tracer tracer(camera, array, aperture_diameter_mm, overfill, sigma_mm, vignetting, transmission, counts.data());
  std::atomic<std::uint64_t> emitted{0}, outside_aperture{0}, missed{0}, outside_sensor{0}, landed{0}, absorbed{0};
  std::atomic<std::size_t> done{0};
  // Progress is told on the calling thread only (it takes part in the loop), when the count has
  // passed its next 1 % since the last report: a caller may wait or throw there without holding
  // up the other threads, and an exception ends the loop (oneTBB cancels its other chunks).
  const std::thread::id caller = std::this_thread::get_id();
  const std::size_t step = std::max<std::size_t>(1, emitters.size() / 100);
  std::size_t next_report = step;  // read and written by the calling thread only
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, emitters.size(), 1), [&](const tbb::blocked_range<std::size_t>& range) {
        RayCounts c;
        for (std::size_t k = range.begin(); k != range.end(); ++k) {
          SplitMix64 rng(stream_seed(seed, k));
          const double rays = std::round(double(rays_per_emitter) * emitters[k].light);
          tracer.trace(emitters[k], std::size_t(rays), rng, c);
          const std::size_t n = ++done;
          if (progress && std::this_thread::get_id() == caller && n >= next_report && n < emitters.size()) {
            next_report = (n / step + 1) * step;
            progress(double(n) / double(emitters.size()));
          }
        }
        emitted += c.emitted;
        outside_aperture += c.outside_aperture;
        missed += c.missed_array;
        outside_sensor += c.outside_sensor;
        landed += c.landed;
        absorbed += c.absorbed;
      });
  if (progress) progress(1.0);
  RenderResult result;
  result.counts = {emitted, outside_aperture, missed, outside_sensor, landed, absorbed};
  result.rays = ImageF(w, h);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, counts.size(), 1 << 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) result.rays.pixels[i] = float(counts[i]);
                    });
  result.image = apply_sensor(result.rays, sensor, seed ^ 0x5e9507ULL);
  return result;
}

}  // namespace

void check_render_options(const RenderOptions& options) {
  check_finite_nonnegative(options.aperture_diameter_mm, "aperture_diameter_mm");
  check_finite_nonnegative(options.brightness_spread, "brightness_spread");
  if (options.brightness_spread > 3) {
    throw InputError("render options: brightness_spread: the spread of a particle's log light, 0 to 3, got " +
                     std::to_string(options.brightness_spread));
  }
}

RenderResult render(const optics::CameraModel& camera, const optics::MicrolensArray& array,
                    std::span<const Point3> particles_mm, const RenderOptions& options, std::uint64_t seed) {
  check_render_options(options);
  std::vector<Emitter> emitters;
  emitters.reserve(particles_mm.size());
  for (std::size_t k = 0; k < particles_mm.size(); ++k) {
    const Point3& p = particles_mm[k];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      throw InputError("render: particle " + std::to_string(k) + " has a non-finite coordinate");
    }
    if (!(camera.object_distance_mm() + p[2] > 0)) {
      throw InputError("render: particle " + std::to_string(k) + " at z = " + std::to_string(p[2]) +
                       " mm is at or behind the main lens (z must be > -s_o = " +
                       std::to_string(-camera.object_distance_mm()) + " mm)");
    }
    double light = 1.0;
    if (options.brightness_spread > 0) {
      // Library distributions are fine here: same machine, same library => same image.
      std::mt19937_64 engine(stream_seed(options.brightness_seed, k));
      const double s = options.brightness_spread;
      light = std::exp(s * std::normal_distribution<double>(0.0, 1.0)(engine) - 0.5 * s * s);
    }
    emitters.push_back({p[0], p[1], p[2], 0, 0, light});
  }
  const double aperture =
      options.aperture_diameter_mm > 0 ? options.aperture_diameter_mm : camera.aperture_diameter_mm();
  return trace_all(camera, array, emitters, options.rays_per_particle, aperture, options.aperture_overfill,
                   options.diffraction_sigma_mm, options.vignetting, options.sensor, options.progress, seed);
}

TargetOptions calibration_target() {
  TargetOptions t;
  t.f_number = 16.0;
  return t;
}

TargetOptions white_target() { return TargetOptions{}; }

RenderResult render_target(const optics::CameraModel& camera, const optics::MicrolensArray& array,
                           const TargetOptions& options, std::uint64_t seed) {
  check_array(array);
  check_finite_nonnegative(options.f_number, "f_number");
  const double f_number = options.f_number > 0 ? options.f_number : camera.main_lens().f_number;
  // Tiles of one lattice cell on the microlens plane, over the array's bounding box plus one
  // pitch, imaged back to the focal plane (x_o = x_m / M).
  double lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  double hi[2] = {-lo[0], -lo[1]};
  for (const auto& c : array.centres_mm) {
    for (int a = 0; a < 2; ++a) {
      lo[a] = std::min(lo[a], c[a]);
      hi[a] = std::max(hi[a], c[a]);
    }
  }
  // An array that overfills the sensor lights the target only where the sensor can see it: the
  // sensor's footprint on the microlens plane plus two pitches.
  const double px = array.lattice.pitch_x_mm, py = array.lattice.pitch_y_mm;
  const auto& sensor = camera.sensor();
  const double seen_lo[2] = {optics::column_to_sensor_mm(sensor, -0.5) - 2 * px,
                             optics::row_to_sensor_mm(sensor, -0.5) - 2 * py};
  const double seen_hi[2] = {optics::column_to_sensor_mm(sensor, sensor.width_px - 0.5) + 2 * px,
                             optics::row_to_sensor_mm(sensor, sensor.height_px - 0.5) + 2 * py};
  for (int a = 0; a < 2; ++a) {
    if (lo[a] < seen_lo[a] && hi[a] > seen_hi[a]) {
      lo[a] = seen_lo[a];
      hi[a] = seen_hi[a];
    }
  }
  const int tx = int(std::ceil((hi[0] - lo[0]) / px)) + 3, ty = int(std::ceil((hi[1] - lo[1]) / py)) + 3;
  const double x0 = 0.5 * (lo[0] + hi[0]) - 0.5 * (tx - 1) * px;
  const double y0 = 0.5 * (lo[1] + hi[1]) - 0.5 * (ty - 1) * py;
  const double m = camera.main_lens().magnification;
  std::vector<Emitter> tiles;
  tiles.reserve(std::size_t(tx) * ty);
  for (int j = 0; j < ty; ++j) {
    for (int i = 0; i < tx; ++i) {
      tiles.push_back({(x0 + i * px) / m, (y0 + j * py) / m, 0.0, px / std::abs(m), py / std::abs(m)});
    }
  }
  return trace_all(camera, array, tiles, options.rays_per_lens, camera.main_lens().focal_length_mm / f_number, 1.0,
                   options.diffraction_sigma_mm, options.vignetting, options.sensor, options.progress, seed);
}

ImageU16 apply_sensor(const ImageF& rays, const SensorModel& sensor, std::uint64_t seed) {
  check_sensor(sensor);
  ImageU16 out(rays.width, rays.height);
  const double max_dn = double((1u << sensor.bit_depth) - 1);
  const bool noisy = sensor.shot_noise || sensor.read_noise_electrons > 0;
  const double dn_per_ray = sensor.electrons_per_ray * sensor.gain_dn_per_electron;
  // Clamped to [0, max] first, so adding 0.5 and truncating rounds to nearest (a libm round()
  // per pixel cost as much as the rest of a noiseless conversion of a 16 Mpixel frame).
  auto to_dn = [&](double dn) { return std::uint16_t(std::clamp(dn, 0.0, max_dn) + 0.5); };
  tbb::parallel_for(tbb::blocked_range<int>(0, rays.height), [&](const tbb::blocked_range<int>& range) {
    for (int y = range.begin(); y != range.end(); ++y) {
      const float* in = rays.pixels.data() + std::size_t(y) * rays.width;
      std::uint16_t* row = out.pixels.data() + std::size_t(y) * rays.width;
      const auto offset = [&](int x) {
        return x < rays.width / 2 ? sensor.dark_offset_dn : sensor.dark_offset_dn + sensor.right_half_offset_dn;
      };
      if (!noisy) {
        for (int x = 0; x < rays.width; ++x) row[x] = to_dn(in[x] * dn_per_ray + offset(x));
        continue;
      }
      // Library distributions are fine here: same machine, same library => same image.
      std::mt19937_64 engine(stream_seed(seed, std::uint64_t(y)));
      std::normal_distribution<double> read(0.0, sensor.read_noise_electrons > 0 ? sensor.read_noise_electrons : 1.0);
      for (int x = 0; x < rays.width; ++x) {
        double electrons = in[x] * sensor.electrons_per_ray;
        if (sensor.shot_noise && electrons > 0) {
          electrons = double(std::poisson_distribution<std::int64_t>(electrons)(engine));
        }
        if (sensor.read_noise_electrons > 0) electrons += read(engine);
        row[x] = to_dn(electrons * sensor.gain_dn_per_electron + offset(x));
      }
    }
  });
  return out;
}

optics::Lattice overfilling_lattice(const optics::CameraModel& camera, optics::LensletLayout layout, double pitch_mm,
                                    double rotation_rad, double offset_x_mm, double offset_y_mm, int margin_lenses) {
  if (!(pitch_mm > 0) || !std::isfinite(pitch_mm) || !std::isfinite(rotation_rad) || !std::isfinite(offset_x_mm) ||
      !std::isfinite(offset_y_mm) || margin_lenses < 0) {
    throw InputError("overfilling array: needs a positive pitch, finite rotation and offset, margin >= 0");
  }
  optics::Lattice l;
  l.layout = layout;
  l.pitch_x_mm = pitch_mm;
  l.pitch_y_mm = layout == optics::LensletLayout::hex ? pitch_mm * std::sqrt(3.0) / 2 : pitch_mm;
  l.rotation_rad = rotation_rad;
  l.offset_x_mm = offset_x_mm;
  l.offset_y_mm = offset_y_mm;
  // The sensor's corners in the array's own (unrotated) frame bound the lenses it can see.
  const auto& s = camera.sensor();
  const double c = std::cos(rotation_rad), sn = std::sin(rotation_rad);
  double reach_a = 0, reach_b = 0;
  for (double col : {-0.5, s.width_px - 0.5}) {
    for (double row : {-0.5, s.height_px - 0.5}) {
      const double dx = optics::column_to_sensor_mm(s, col) - offset_x_mm;
      const double dy = optics::row_to_sensor_mm(s, row) - offset_y_mm;
      reach_a = std::max(reach_a, std::abs(c * dx - sn * dy));
      reach_b = std::max(reach_b, std::abs(sn * dx + c * dy));
    }
  }
  l.count_x = 2 * (int(std::ceil(reach_a / l.pitch_x_mm)) + margin_lenses) + 1;
  l.count_y = 2 * (int(std::ceil(reach_b / l.pitch_y_mm)) + margin_lenses) + 1;
  return l;
}

optics::MicrolensArray jittered_array(const optics::Lattice& lattice, double sigma_mm, std::uint64_t seed) {
  check_finite_nonnegative(sigma_mm, "lens jitter sigma_mm");
  optics::MicrolensArray array = optics::MicrolensArray::from_lattice(lattice);
  SplitMix64 rng(stream_seed(seed, 0));
  for (auto& c : array.centres_mm) {
    double a, b;
    rng.normal_pair(a, b);
    c[0] += sigma_mm * a;
    c[1] += sigma_mm * b;
  }
  return array;
}

}  // namespace plenopiv::sim
