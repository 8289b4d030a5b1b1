// Resampling a raw image onto an axis-aligned virtual microlens lattice (see the header).
#include "core/lightfield/lattice_resampling.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/base/errors.hpp"
#include "core/lightfield/light_field.hpp"

namespace plenopiv::lightfield {
namespace {
// Lens weights summing to at least this cover a virtual lens wholly (float rounding aside).
constexpr float kWhole = 0.999f;
}  // namespace

optics::MicrolensArray axis_aligned_lattice(const optics::MicrolensArray& calibrated) {
  const optics::Lattice& c = calibrated.lattice;
  optics::Lattice v = c;
  v.layout = optics::LensletLayout::rect;
  v.rotation_rad = 0;
  if (c.layout == optics::LensletLayout::hex) {
    v.pitch_y_mm = c.pitch_x_mm;
    v.count_y = int(std::floor((c.count_y - 1) * c.pitch_y_mm / c.pitch_x_mm + 1e-9)) + 1;
  }
  return optics::MicrolensArray::from_lattice(v);
}

LatticeResampler::LatticeResampler(const optics::CameraModel& camera, const optics::MicrolensArray& calibrated,
                                   const ImageF& white, double whole_lens_px)
    : virtual_(axis_aligned_lattice(calibrated)), width_(camera.sensor().width_px), height_(camera.sensor().height_px) {
  const optics::SensorSpec& s = camera.sensor();
  if (white.width != width_ || white.height != height_) {
    throw InputError("white correction is " + std::to_string(white.width) + " x " + std::to_string(white.height) +
                     " pixels, the camera file's sensor is " + std::to_string(width_) + " x " +
                     std::to_string(height_));
  }
  for (std::size_t k = 0; k < white.size(); ++k) {
    if (!std::isfinite(white.pixels[k]) || white.pixels[k] < 0) {
      throw InputError("white correction: pixel (" + std::to_string(k % white.width) + ", " +
                       std::to_string(k / white.width) + ") is not a finite, non-negative value");
    }
  }
  if (!(whole_lens_px >= 0) || !std::isfinite(whole_lens_px)) {
    throw InputError("lattice resampling: the nearest-lens tolerance must be a finite number >= 0 px, got " +
                     std::to_string(whole_lens_px));
  }
  const optics::Lattice& cl = calibrated.lattice;
  if (cl.count_x < 2 || cl.count_y < 2 || calibrated.centres_mm.size() != std::size_t(cl.count())) {
    throw InputError("microlens array: needs at least 2 x 2 lenses and one centre per lens");
  }
  const double s_i = camera.image_distance_mm(), f_l = camera.microlens().focal_length_mm;
  const auto spot_px = [&](const std::array<double, 2>& lens_mm) {
    return std::array<double, 2>{optics::sensor_mm_to_column(s, optics::lens_centre_to_spot_mm(lens_mm[0], s_i, f_l)),
                                 optics::sensor_mm_to_row(s, optics::lens_centre_to_spot_mm(lens_mm[1], s_i, f_l))};
  };

  // Which virtual lens each pixel sits behind: the nearest spot, which on the axis-aligned
  // lattice is the nearest spot column and the nearest spot row (pixels beyond the array take the
  // outermost lens: they see beyond the aperture there, where the white image is 0 anyway).
  std::vector<std::array<double, 2>> virtual_spots(virtual_.centres_mm.size());
  for (std::size_t v = 0; v < virtual_spots.size(); ++v) virtual_spots[v] = spot_px(virtual_.centres_mm[v]);
  const optics::Lattice& vl = virtual_.lattice;
  const auto nearest = [](double spot_index, int count) {
    return int(std::clamp(std::lround(spot_index), 0L, long(count - 1)));
  };
  const double pitch_c = virtual_spots[1][0] - virtual_spots[0][0];
  const double pitch_r = virtual_spots[std::size_t(vl.count_x)][1] - virtual_spots[0][1];
  lens_column_.resize(std::size_t(width_));
  lens_row_.resize(std::size_t(height_));
  for (int c = 0; c < width_; ++c)
    lens_column_[std::size_t(c)] = nearest((c - virtual_spots[0][0]) / pitch_c, vl.count_x);
  for (int r = 0; r < height_; ++r)
    lens_row_[std::size_t(r)] = nearest((r - virtual_spots[0][1]) / pitch_r, vl.count_y);

  // Per virtual lens, the calibrated lenses around its centre and their raw-pixel taps.
  const LatticeInterpolator interpolator(cl);
  const std::size_t nv = virtual_.centres_mm.size();
  std::vector<std::array<Tap, 4>> taps(nv);
  std::vector<int> counts(nv, 0);
  std::vector<char> nearest_only(nv, 0);
  std::vector<float> weight_sums(nv, 0.f);
  tbb::parallel_for(std::size_t(0), nv, [&](std::size_t v) {
    const std::array<double, 2> target = virtual_.centres_mm[v];
    std::array<double, 2> at = target;
    std::array<int, 4> lens{};
    std::array<float, 4> weight{};
    // Lattice coordinates of the fitted lattice, then corrected until the bilinear blend of the
    // four measured centres is the target (a few iterations: departures are a fraction of a pitch).
    // At the array's edge, where lenses are missing, the fitted lattice's weights stand.
    for (int it = 0; it < 4; ++it) {
      const int n = interpolator.weights(at[0], at[1], lens, weight);
      float sum = 0;
      for (int q = 0; q < n; ++q) sum += weight[std::size_t(q)];
      if (sum < kWhole) break;
      std::array<double, 2> blend{0, 0};
      for (int q = 0; q < n; ++q)
        for (int a = 0; a < 2; ++a)
          blend[std::size_t(a)] +=
              weight[std::size_t(q)] * calibrated.centres_mm[std::size_t(lens[std::size_t(q)])][std::size_t(a)];
      for (int a = 0; a < 2; ++a) at[std::size_t(a)] += target[std::size_t(a)] - blend[std::size_t(a)];
    }
    const int n = interpolator.weights(at[0], at[1], lens, weight);
    const std::array<double, 2> vs = virtual_spots[v];
    for (int q = 0; q < n; ++q) {
      const std::array<double, 2> cs = spot_px(calibrated.centres_mm[std::size_t(lens[std::size_t(q)])]);
      // Same offset from the calibrated spot as from the virtual one: the same aperture point
      // (eq 1), at the nearest raw pixel (see the header for why not bilinear).
      Tap& t = taps[v][std::size_t(q)];
      t.dc = std::int32_t(std::lround(cs[0] - vs[0]));
      t.dr = std::int32_t(std::lround(cs[1] - vs[1]));
      t.w = weight[std::size_t(q)];
      weight_sums[v] += t.w;
    }
    counts[v] = n;
    nearest_only[v] = n == 1;
    if (n < 2) return;
    int best = 0;
    for (int q = 1; q < n; ++q)
      if (taps[v][std::size_t(q)].w > taps[v][std::size_t(best)].w) best = q;
    const std::array<double, 2>& nearest = calibrated.centres_mm[std::size_t(lens[std::size_t(best)])];
    const double departure_px =
        std::max(std::abs(nearest[0] - target[0]), std::abs(nearest[1] - target[1])) / s.pixel_pitch_mm;
    if (departure_px <= whole_lens_px) {
      taps[v][0] = taps[v][std::size_t(best)];
      taps[v][0].w = weight_sums[v];
      counts[v] = 1;
      nearest_only[v] = 1;
    }
  });
  tap_start_.assign(nv + 1, 0);
  for (std::size_t v = 0; v < nv; ++v) {
    tap_start_[v + 1] = tap_start_[v] + std::uint32_t(counts[v]);
    for (int q = 0; q < counts[v]; ++q) taps_.push_back(taps[v][std::size_t(q)]);
    coverage_.nearest += nearest_only[v];
    if (counts[v] == 0) {
      ++coverage_.none;
    } else if (weight_sums[v] >= kWhole) {
      ++coverage_.full;
    } else {
      ++coverage_.partial;
    }
  }
  apply(white, white_);
}

void LatticeResampler::apply(const ImageF& in, ImageF& out) const {
  if (out.width != width_ || out.height != height_) out = ImageF(width_, height_);
  const std::size_t nx = std::size_t(virtual_.lattice.count_x);
  tbb::parallel_for(0, height_, [&](int row) {
    const std::size_t lens_row = std::size_t(lens_row_[std::size_t(row)]) * nx;
    for (int col = 0; col < width_; ++col) {
      const std::size_t v = lens_row + std::size_t(lens_column_[std::size_t(col)]);
      float sum = 0;
      for (std::uint32_t t = tap_start_[v]; t < tap_start_[v + 1]; ++t) {
        const Tap& tap = taps_[t];
        const int r = row + tap.dr, c = col + tap.dc;
        // Off the sensor counts as dark, in the image and in its white alike.
        if (r >= 0 && r < height_ && c >= 0 && c < width_) sum += tap.w * in.pixels[std::size_t(r) * width_ + c];
      }
      out.pixels[std::size_t(row) * width_ + col] = sum;
    }
  });
}

void LatticeResampler::resample(const ImageF& raw, ImageF& out) const {
  if (raw.width != width_ || raw.height != height_) {
    throw InputError("raw image is " + std::to_string(raw.width) + " x " + std::to_string(raw.height) +
                     " pixels, the resampler's sensor is " + std::to_string(width_) + " x " + std::to_string(height_));
  }
  apply(raw, out);
}

ImageF LatticeResampler::resample(const ImageF& raw) const {
  ImageF out;
  resample(raw, out);
  return out;
}

}  // namespace plenopiv::lightfield
