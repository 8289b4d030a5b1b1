// The light field of a raw plenoptic image: (x, y, u, v) per pixel (eq 1) and the rectified 4D
// light field L(lx, ly, u, v) resampled from it (sec 3.1-3.2).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::lightfield {

// Two-plane coordinates of every pixel (eq 1 with the sign of core/optics/microlens_array.hpp):
// (x, y) the centre of the lens the pixel sits behind (microlens plane, mm), (u, v) the point of
// the main-lens aperture it sees (mm from the optical axis). Pixels behind no lens: lens = -1,
// coordinates 0. Arrays are row-major like the image.
struct PixelRays {
  int width = 0;
  int height = 0;
  std::vector<std::int32_t> lens;  // j * count_x + i
  std::vector<float> x_mm, y_mm, u_mm, v_mm;
};
PixelRays pixel_rays(const optics::CameraModel& camera, const optics::MicrolensArray& lenses);

// Regular aperture sampling of the rectified light field: sample k of n sits at
// u_k = (k - (n - 1) / 2) * du, and du = aperture diameter / n, so that the n samples tile the
// aperture. The default n is the microlens image diameter in pixels, rounded: one sample per pixel.
struct ApertureSampling {
  int n_u = 0;
  int n_v = 0;
  double du_mm = 0;
  double dv_mm = 0;
  double u(int k) const { return (k - 0.5 * (n_u - 1)) * du_mm; }
  double v(int k) const { return (k - 0.5 * (n_v - 1)) * dv_mm; }
  static ApertureSampling for_camera(const optics::CameraModel& camera, int n = 0);
};

// L(lx, ly, u, v): for lens (lx, ly) and aperture sample (iu, iv), the raw image interpolated
// bilinearly at the sensor point that sample maps to through that lens (eq 1 inverted:
// x_s = spot - u f_l / s_i, spot = lens_centre_to_spot_mm of the lens's own centre), divided by
// the white correction there when one is given. Samples outside the aperture disc, off the
// sensor, or where the white correction is below `min_white` are invalid (value 0, valid 0).
// Layout [iv][iu][ly][lx], lx fastest: each (iu, iv) is one sub-aperture view (perspective).
struct LightField {
  optics::MicrolensArray lenses;  // lens (lx, ly) sits at lenses.centre(lx, ly), mm
  ApertureSampling sampling;
  std::vector<float> values;
  std::vector<std::uint8_t> valid;

  int nx() const { return lenses.lattice.count_x; }
  int ny() const { return lenses.lattice.count_y; }
  std::size_t index(int lx, int ly, int iu, int iv) const {
    return ((std::size_t(iv) * sampling.n_u + iu) * ny() + ly) * nx() + lx;
  }
  float at(int lx, int ly, int iu, int iv) const { return values[index(lx, ly, iu, iv)]; }
};

struct RectifyOptions {
  ApertureSampling sampling;  // n_u == 0: ApertureSampling::for_camera
  double min_white = 0.1;
};

// `raw` must be the sensor's size with finite, non-negative values; `white` (may be null) the
// white correction of the calibration (fig 15). Throws InputError naming what does not match.
LightField rectify(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& raw,
                   const ImageF* white, const RectifyOptions& options = {});

// Interpolates per-lens quantities at microlens-plane points, on the lattice (per-lens departures
// from it, a fraction of a pixel, are below the resolution of one value per lens).
class LatticeInterpolator {
 public:
  explicit LatticeInterpolator(const optics::Lattice& lattice);
  // Up to four (lens index, weight) pairs whose weighted sum interpolates a per-lens quantity at
  // (x, y): bilinear in (i, j) for rect; for hex linear along each of the two neighbouring rows,
  // then linear between them. Lenses outside the array are left out (the return value says how
  // many remain; their weights then sum to less than 1).
  int weights(double x_mm, double y_mm, std::array<int, 4>& lens, std::array<float, 4>& weight) const;
  // The same from continuous lattice coordinates: a along a row in pitches with lens (i, j) at
  // a = i (+-0.25 for hex rows as optics::Lattice), b = j. The lattice-plane offset of a
  // microlens-plane vector (dx, dy) mm is `to_lattice`.
  int weights_at(double a, double b, std::array<int, 4>& lens, std::array<float, 4>& weight) const;
  std::array<double, 2> to_lattice(double dx_mm, double dy_mm) const;

 private:
  optics::Lattice lattice_;
  double cos_ = 1, sin_ = 0;
};

}  // namespace plenopiv::lightfield
