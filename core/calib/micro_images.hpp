// Micro-images of a white or calibration image: rough centres, the mean micro-image (template)
// and per-lens template fits with their uncertainties.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/base/image.hpp"
#include "core/calib/lattice_fit.hpp"

namespace plenopiv::calib {

// Local maxima of the image smoothed by a Gaussian of `smoothing` x the pitch, at least a third
// of a pitch apart and above background + `fraction` x (bright level - background): one near the
// centre of each lit micro-image, white (a vignetted disk) or stopped down (a spot). Levels are
// percentiles of the smoothed image (background 2 %, bright 99.5 %).
struct Candidates {
  std::vector<std::array<double, 2>> points;  // (column, row)
  double background = 0;
  double bright = 0;
  double threshold = 0;
};
Candidates find_candidates(const ImageF& image, double pitch_px, double smoothing = 0.2, double fraction = 0.3);

// Robust pixel noise (counts): 1.4826 x the median absolute difference between the image and its
// 3 x 3 median, scaled to one pixel's noise.
double pixel_noise(const ImageF& image);

// Replaces isolated hot pixels (more than `ratio` times every neighbour's signal above
// `background`, and 10 noise sigmas above the brightest neighbour) by their neighbours' median,
// except within `keep_radius` pixels of a point in `keep` (a stopped-down spot may fall in one
// pixel). Returns how many were replaced.
int remove_hot_pixels(ImageF& image, double background, double noise, double ratio,
                      const std::vector<std::array<double, 2>>& keep, double keep_radius);

// One lens's fit of the template: image = b + (a + g . (p - start) / pitch) T(p - centre) over the
// lens's Voronoi cell of the lattice (pixels on the sensor), by Gauss-Newton with Tukey weights
// (dust shadows, hot pixels and light from outside the model fall out).
struct LensFit {
  std::array<double, 2> centre{0, 0};  // (column, row)
  double sigma = 0;                    // centre uncertainty per axis, pixels (1 sigma)
  double amplitude = 0;                // a
  double amplitude_sigma = 0;
  double background = 0;             // b
  std::array<double, 2> tilt{0, 0};  // g: brightness change across one pitch, counts
  double visible = 0;                // share of the lens's cell on the sensor
  double outliers = 0;               // share of its pixels the robust weights set aside
  double noise = 0;                  // robust residual scale, counts
  bool converged = false;
};

// The mean micro-image: every lens's pixels, minus its background and divided by its brightness
// (with its tilt), binned by their offset from its centre on a grid a few times finer than the
// pixels, averaged and made point-symmetric (T(d) = T(-d): a round aperture seen through a lens
// is symmetric about the chief ray, which defines the centre). Normalised to 0 at its floor, 1 at
// its peak.
class MicroImageTemplate {
 public:
  // `lenses` (centres, brightness, background, tilt) and `use` (which of them contribute) from a
  // previous fit, or from candidates with tilt 0.
  MicroImageTemplate(const ImageF& image, const RawLattice& lattice, const std::vector<std::array<int, 2>>& sites,
                     const std::vector<LensFit>& lenses, const std::vector<std::uint8_t>& use);

  double value(double dx, double dy) const;
  void value_and_gradient(double dx, double dy, double& v, double& gx, double& gy) const;
  double radius_px() const { return radius_; }  // offsets beyond this are not modelled

  // Where the micro-image falls to `level` of its centre, along the directions to the corners of
  // the lattice cell (where neighbours' images are farthest), averaged: its radius, pixels. A
  // value at the cell corner means it never falls that far there.
  double radius_at(double level) const;
  // The distance from the centre to the lattice cell's corners, pixels.
  double corner_distance() const { return corner_; }

 private:
  double sample(const std::vector<float>& grid, double dx, double dy) const;

  RawLattice lattice_;
  double radius_ = 0;
  double corner_ = 0;
  int oversample_ = 1;
  int n_ = 0;  // grid is n_ x n_, offset 0 at index (n_ - 1) / 2
  std::vector<float> value_, grad_x_, grad_y_;
  std::vector<std::array<float, 3>> packed_;  // value and gradient together, for the fits
};

// Pixel noise as a function of signal: variance = floor + gain x (signal above background), from
// read noise and photon noise (and the template's own mismatch, which grows with the signal too).
// robust = false: plain least squares with equal weights (a first pass, before it is known).
struct NoiseModel {
  bool robust = false;
  double floor = 0;  // counts^2
  double gain = 0;   // counts^2 per count
};

// Fits every site (i, j) of `lattice` in `sites`, starting from `start` (centre, brightness and
// background; its tilt is kept fixed when `fit_tilt` is false). With a robust noise model each
// pixel weighs 1 / variance times Tukey's biweight of its normalised residual. Parallel over
// lenses; each lens's result does not depend on the thread count.
std::vector<LensFit> fit_lenses(const ImageF& image, const RawLattice& lattice,
                                const std::vector<std::array<int, 2>>& sites, const std::vector<LensFit>& start,
                                const MicroImageTemplate& shape, bool fit_tilt, const NoiseModel& noise);

// The noise model from the residuals of fitted lenses (those with `use` set): robust variances in
// bins of signal, and a straight line through them.
NoiseModel estimate_noise_model(const ImageF& image, const RawLattice& lattice,
                                const std::vector<std::array<int, 2>>& sites, const std::vector<LensFit>& fits,
                                const std::vector<std::uint8_t>& use, const MicroImageTemplate& shape);

// The pixels of the Voronoi cell of lens (i, j) that lie on the image: calls f(x, y).
template <typename F>
void for_each_cell_pixel(const RawLattice& lattice, int i, int j, int width, int height, F&& f) {
  const auto c = lattice.site(i, j);
  const double reach = 0.8 * std::max(lattice.px, lattice.py) + 1;
  const int x0 = std::max(0, int(std::floor(c[0] - reach))), x1 = std::min(width - 1, int(std::ceil(c[0] + reach)));
  const int y0 = std::max(0, int(std::floor(c[1] - reach))), y1 = std::min(height - 1, int(std::ceil(c[1] + reach)));
  const double cr = std::cos(lattice.rotation), sr = std::sin(lattice.rotation);
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      const auto n = lattice.nearest(x, y, cr, sr);
      if (n[0] == i && n[1] == j) f(x, y);
    }
  }
}

}  // namespace plenopiv::calib
