// Microlens calibration: micro-images found on a lattice, per-lens template fits, a lattice with
// the distortion the data support, per-lens centres by evidence, the white's fill and axis.
#include "core/calib/calibration.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>

#include "core/base/errors.hpp"
#include "core/calib/lattice_fit.hpp"
#include "core/calib/micro_images.hpp"

namespace plenopiv::calib {
namespace {

// The spot lattice in pixels, relative to the sensor centre, indexed as optics::Lattice: what the
// pixel-to-lens map works in.
struct PxLattice {
  bool hex = false;
  int nx = 0, ny = 0;
  double px = 0, py = 0, th = 0, ox = 0, oy = 0;

  double shift(int j) const { return hex ? ((j & 1) ? 0.25 : -0.25) : 0.0; }
  double la(int i, int j) const { return i - 0.5 * (nx - 1) + shift(j); }
  double lb(int j) const { return j - 0.5 * (ny - 1); }
  std::array<double, 2> position(int i, int j) const {
    const double a = la(i, j) * px, b = lb(j) * py;
    const double c = std::cos(th), s = std::sin(th);
    return {c * a + s * b + ox, -s * a + c * b + oy};
  }
};

std::string fmt(double v, int precision = 3) {
  std::ostringstream s;
  s.precision(precision);
  s << std::fixed << v;
  return s.str();
}

// Thousands separated by a space, as the messages read ("55 777").
std::string count_str(long v) {
  std::string digits = std::to_string(v), out;
  for (std::size_t k = 0; k < digits.size(); ++k) {
    if (k > 0 && (digits.size() - k) % 3 == 0) out += ' ';
    out += digits[k];
  }
  return out;
}

// Tukey's biweight at 4.685 (normalised residual z).
double tukey_weight(double z) {
  const double u = z / 4.685;
  return std::abs(u) < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
}

double median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  const std::size_t k = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

void check_image(const optics::SensorSpec& sensor, const ImageF& image, const std::string& what) {
  if (image.width != sensor.width_px || image.height != sensor.height_px) {
    throw InputError(what + " is " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                     " pixels, the camera file's sensor is " + std::to_string(sensor.width_px) + " x " +
                     std::to_string(sensor.height_px));
  }
  for (std::size_t k = 0; k < image.size(); ++k) {
    if (!std::isfinite(image.pixels[k])) {
      throw InputError(what + ": pixel (" + std::to_string(k % std::size_t(image.width)) + ", " +
                       std::to_string(k / std::size_t(image.width)) + ") is " + std::to_string(image.pixels[k]) +
                       "; values must be finite");
    }
  }
}

// Cat's-eye vignetting by a second stop (the lens barrel): every micro-image is the aperture's
// disk, and beyond a field radius r0 from the optical axis a second disk, moving off it in
// proportion to the field, cuts a sliver off one side whose depth grows in proportion to
// r - r0, its area as depth^1.5 (then faster). So the micro-images' areas follow
//   A(r) = A0 - k1 (r - r0)_+^1.5 - k2 (r - r0)_+^2.5,  r = |lens - axis|,
// which a few hundred lenses fix far better than any one lens's area: where the lenses stop being
// whole (r0), and the optical axis (the fall-off's centre, whatever the target's lighting).
struct Vignetting {
  bool found = false;
  std::array<double, 2> axis{0, 0};
  double axis_sigma = 0, r0 = 0, r0_sigma = 0, a0 = 0;
  double drop = 0;  // relative area lost at the farthest lens
};

// What the per-lens stage measured, before the array is chosen.
struct Measured {
  RawLattice lattice;
  std::vector<std::array<int, 2>> sites;
  std::vector<LensFit> fits;
  std::vector<std::uint8_t> whole;      // micro-image wholly on the sensor
  std::vector<std::uint8_t> present;    // a lit micro-image (whole or partial)
  std::vector<std::uint8_t> flawed;     // present and whole, but its fit is not to be trusted
  std::vector<std::uint8_t> vignetted;  // present and whole, its micro-image cut by vignetting
  Vignetting vignetting;                // the cat's-eye fall-off, where found
  SpotImageStats stats;
  double image_radius_px = 0;  // the micro-image's extent from its centre
  // Non-empty when the lattice took the camera file's pitch to be found: it stands only if the
  // white shows overlapping micro-images (measure_white refuses them), else this error is the answer.
  std::string doubt;
};

// When the rows are as far apart as the other layout's: say so.
std::string layout_hint(const RawLattice& lat, const optics::CameraModel& camera) {
  const double ratio = lat.py / lat.px;
  const bool looks_hex = std::abs(ratio - std::sqrt(3.0) / 2) < 0.03, looks_rect = std::abs(ratio - 1) < 0.03;
  const bool file_hex = camera.microlens().layout == optics::LensletLayout::hex;
  if (looks_hex && !file_hex) return "; its rows are sqrt(3)/2 of the pitch apart, as a hex array's: microlens.layout";
  if (looks_rect && file_hex) return "; its rows are one pitch apart, as a rect array's: microlens.layout";
  return "";
}

// "spots" or "micro-images", as the messages name what they found.
const char* things(CentreSource kind) { return kind == CentreSource::spots ? "spots" : "micro-images"; }

std::string image_name(CentreSource kind) { return kind == CentreSource::spots ? "calibration image" : "white image"; }

// The lenses a calibration should find when all goes well: the camera file's counts when they
// fit on the sensor, else as many as the sensor holds whole.
long expected_lenses(const optics::CameraModel& camera) { return camera.lens_count(); }

// The smooth field of micro-image tilts: a quadratic in the image position fitted to the tilts of
// the `good` lenses in `free` (robustly: Huber weights), and written into `held` for every lens.
void smooth_tilt(const std::vector<LensFit>& free, const std::vector<std::uint8_t>& good, std::vector<LensFit>& held) {
  double cx = 0, cy = 0, sx = 1, sy = 1;
  {
    double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
    for (const LensFit& f : free) {
      for (int a = 0; a < 2; ++a) {
        lo[a] = std::min(lo[a], f.centre[std::size_t(a)]);
        hi[a] = std::max(hi[a], f.centre[std::size_t(a)]);
      }
    }
    cx = 0.5 * (lo[0] + hi[0]);
    cy = 0.5 * (lo[1] + hi[1]);
    sx = std::max(1.0, 0.5 * (hi[0] - lo[0]));
    sy = std::max(1.0, 0.5 * (hi[1] - lo[1]));
  }
  auto terms = [&](const std::array<double, 2>& p, double t[6]) {
    const double u = (p[0] - cx) / sx, v = (p[1] - cy) / sy;
    t[0] = 1;
    t[1] = u;
    t[2] = v;
    t[3] = u * u;
    t[4] = u * v;
    t[5] = v * v;
  };
  cv::Vec<double, 6> coef[2];
  for (int axis = 0; axis < 2; ++axis) {
    std::vector<double> w(free.size(), 1.0);
    for (int it = 0; it < 4; ++it) {
      cv::Matx<double, 6, 6> a = cv::Matx<double, 6, 6>::zeros();
      cv::Vec<double, 6> b = cv::Vec<double, 6>::all(0);
      std::vector<double> res;
      for (std::size_t k = 0; k < free.size(); ++k) {
        if (!good[k] || !free[k].converged) continue;
        double t[6];
        terms(free[k].centre, t);
        for (int p = 0; p < 6; ++p) {
          b[p] += w[k] * t[p] * free[k].tilt[std::size_t(axis)];
          for (int q = 0; q < 6; ++q) a(p, q) += w[k] * t[p] * t[q];
        }
      }
      if (!cv::solve(a, b, coef[axis], cv::DECOMP_SVD)) coef[axis] = cv::Vec<double, 6>::all(0);
      for (std::size_t k = 0; k < free.size(); ++k) {
        if (!good[k] || !free[k].converged) continue;
        double t[6];
        terms(free[k].centre, t);
        double m = 0;
        for (int p = 0; p < 6; ++p) m += coef[axis][p] * t[p];
        res.push_back(std::abs(free[k].tilt[std::size_t(axis)] - m));
      }
      const double scale = 1.4826 * median(res) + 1e-12;
      std::size_t q = 0;
      for (std::size_t k = 0; k < free.size(); ++k) {
        if (!good[k] || !free[k].converged) continue;
        const double r = res[q++] / (1.345 * scale);
        w[k] = r <= 1 ? 1.0 : 1.0 / r;
      }
    }
  }
  for (std::size_t k = 0; k < held.size(); ++k) {
    double t[6];
    terms(held[k].centre, t);
    for (int axis = 0; axis < 2; ++axis) {
      double m = 0;
      for (int p = 0; p < 6; ++p) m += coef[axis][p] * t[p];
      held[k].tilt[std::size_t(axis)] = m;
    }
  }
}

// Each lens's light over its centre's level (both above its fitted background): the area its
// micro-image would have as a flat disk. The lens barrel cuts off-axis micro-images into cat's
// eyes, which pass less light for the same centre level; natural vignetting and an unevenly lit
// target dim both alike and leave it. NaN where it cannot be taken.
std::vector<double> micro_image_areas(const ImageF& image, const RawLattice& lat,
                                      const std::vector<std::array<int, 2>>& sites, const std::vector<LensFit>& fits) {
  std::vector<double> area(sites.size(), std::nan(""));
  tbb::parallel_for(std::size_t(0), sites.size(), [&](std::size_t k) {
    const LensFit& f = fits[k];
    if (!f.converged) return;
    double light = 0, centre = 0;
    int central = 0;
    for_each_cell_pixel(lat, sites[k][0], sites[k][1], image.width, image.height, [&](int x, int y) {
      const double v = image.at(x, y) - f.background;
      light += v;
      if (std::hypot(x - f.centre[0], y - f.centre[1]) <= 0.2 * lat.px) {
        centre += v;
        ++central;
      }
    });
    if (central > 0 && centre > 0) area[k] = light / (centre / central);
  });
  return area;
}

// Each value replaced by the median of those of the lenses within one row and column of it (the
// lens itself left out), over lenses with a finite value in `use`; NaN where none.
std::vector<double> neighbourhood_median(const std::vector<std::array<int, 2>>& sites, const std::vector<double>& value,
                                         const std::vector<std::uint8_t>& use) {
  int i0 = 1 << 30, j0 = 1 << 30, i1 = -(1 << 30), j1 = -(1 << 30);
  for (const auto& s : sites) {
    i0 = std::min(i0, s[0]);
    i1 = std::max(i1, s[0]);
    j0 = std::min(j0, s[1]);
    j1 = std::max(j1, s[1]);
  }
  const int nx = i1 - i0 + 1, ny = j1 - j0 + 1;
  std::vector<int> at(std::size_t(std::max(nx, 0)) * std::max(ny, 0), -1);
  for (std::size_t k = 0; k < sites.size(); ++k) at[std::size_t(sites[k][1] - j0) * nx + (sites[k][0] - i0)] = int(k);
  std::vector<double> out(sites.size(), std::nan(""));
  for (std::size_t k = 0; k < sites.size(); ++k) {
    std::vector<double> near;
    for (int j = std::max(j0, sites[k][1] - 1); j <= std::min(j1, sites[k][1] + 1); ++j) {
      for (int i = std::max(i0, sites[k][0] - 1); i <= std::min(i1, sites[k][0] + 1); ++i) {
        const int q = at[std::size_t(j - j0) * nx + (i - i0)];
        if (q >= 0 && std::size_t(q) != k && use[std::size_t(q)] && std::isfinite(value[std::size_t(q)])) {
          near.push_back(value[std::size_t(q)]);
        }
      }
    }
    if (!near.empty()) out[k] = median(near);
  }
  return out;
}

// Without a radial cat's-eye fall-off (fit_vignetting), lenses whose micro-image areas fall short
// of their neighbours' by more than five times one area's noise: a shadow or a stop that cuts
// them unlike the rest; their centres are pulled like a cat's eye's.
std::vector<std::uint8_t> vignetted_lenses(const std::vector<std::array<int, 2>>& sites,
                                           const std::vector<double>& area, const std::vector<std::uint8_t>& use) {
  std::vector<std::uint8_t> out(area.size(), 0);
  const std::vector<double> near = neighbourhood_median(sites, area, use);
  std::vector<double> dev;
  for (std::size_t k = 0; k < area.size(); ++k) {
    if (use[k] && std::isfinite(area[k]) && std::isfinite(near[k])) dev.push_back(std::abs(area[k] - near[k]));
  }
  if (dev.size() < 10) return out;
  // |area - neighbours' median| spreads by one area's noise and the median's: ~1.06 of one.
  const double single = 1.4826 * median(dev) / 1.06;
  for (std::size_t k = 0; k < area.size(); ++k) {
    out[k] =
        std::isfinite(area[k]) && std::isfinite(near[k]) && area[k] < near[k] - std::max(0.003 * near[k], 5 * single);
  }
  return out;
}

// The cat's-eye model fitted to per-lens areas at positions p (pixels), robustly (dust).
Vignetting fit_vignetting(const std::vector<std::array<double, 2>>& p, const std::vector<double>& area, double pitch) {
  Vignetting v;
  std::vector<double> sorted;
  for (double a : area)
    if (std::isfinite(a)) sorted.push_back(a);
  if (sorted.size() < 30) return v;
  std::sort(sorted.begin(), sorted.end());
  const double a_ref = sorted[std::size_t(0.9 * double(sorted.size() - 1))];
  // Start: the centroid of the lenses within 1 % of the full area, and their reach from it.
  double cx = 0, cy = 0;
  int nc = 0;
  for (std::size_t k = 0; k < p.size(); ++k) {
    if (std::isfinite(area[k]) && area[k] > 0.99 * a_ref) {
      cx += p[k][0];
      cy += p[k][1];
      ++nc;
    }
  }
  if (nc < 5 || nc == int(sorted.size())) return v;
  cx /= nc;
  cy /= nc;
  std::vector<double> reach;
  for (std::size_t k = 0; k < p.size(); ++k)
    if (std::isfinite(area[k]) && area[k] > 0.99 * a_ref) reach.push_back(std::hypot(p[k][0] - cx, p[k][1] - cy));
  std::sort(reach.begin(), reach.end());
  // Parameters: axis x, y, A0, r0, k1, k2 (r in pitches for conditioning).
  double th[6] = {cx, cy, a_ref, reach[std::size_t(0.8 * double(reach.size() - 1))] / pitch, 0, 0};
  auto model = [&](const double* t, const std::array<double, 2>& q) {
    const double r = std::hypot(q[0] - t[0], q[1] - t[1]) / pitch;
    const double x = std::max(0.0, r - t[3]);
    return t[2] - t[4] * std::pow(x, 1.5) - t[5] * std::pow(x, 2.5);
  };
  std::vector<double> w(p.size(), 1.0);
  double s2 = 0;
  cv::Matx<double, 6, 6> jtj;
  for (int it = 0; it < 40; ++it) {
    jtj = cv::Matx<double, 6, 6>::zeros();
    cv::Vec<double, 6> jtr = cv::Vec<double, 6>::all(0);
    std::vector<double> res;
    double chi2 = 0, wsum = 0;
    for (std::size_t k = 0; k < p.size(); ++k) {
      if (!std::isfinite(area[k])) continue;
      const double m0 = model(th, p[k]);
      const double r = area[k] - m0;
      res.push_back(std::abs(r));
      double j[6];
      for (int a = 0; a < 6; ++a) {
        double t2[6];
        std::copy(th, th + 6, t2);
        const double h = a < 2    ? 0.01 * pitch
                         : a == 2 ? 1e-6 * a_ref
                         : a == 3 ? 1e-3
                                  : 1e-6 * a_ref + 1e-3 * std::abs(th[a]);
        t2[a] += h;
        j[a] = (model(t2, p[k]) - m0) / h;
      }
      for (int a = 0; a < 6; ++a) {
        jtr[a] += w[k] * j[a] * r;
        for (int b = 0; b < 6; ++b) jtj(a, b) += w[k] * j[a] * j[b];
      }
      chi2 += w[k] * r * r;
      wsum += w[k];
    }
    s2 = chi2 / std::max(1.0, wsum - 6);
    // Tukey weights against dust and flawed lenses, from the robust scale of the residuals.
    const double scale = 1.4826 * median(res) + 1e-12;
    std::size_t q = 0;
    for (std::size_t k = 0; k < p.size(); ++k) {
      if (!std::isfinite(area[k])) continue;
      w[k] = tukey_weight((area[k] - model(th, p[k])) / scale);
      (void)q;
    }
    cv::Matx<double, 6, 6> damped = jtj;
    for (int a = 0; a < 6; ++a) damped(a, a) = damped(a, a) * (1 + 1e-3) + 1e-12;
    cv::Vec<double, 6> step;
    if (!cv::solve(damped, jtr, step, cv::DECOMP_CHOLESKY)) return v;
    const double move = std::hypot(step[0], step[1]);
    const double shrink = move > 2 * pitch ? 2 * pitch / move : 1.0;
    for (int a = 0; a < 6; ++a) th[a] += shrink * step[a];
    th[3] = std::max(0.0, th[3]);
    if (move < 1e-3 && it > 5) break;
  }
  cv::Matx<double, 6, 6> cov;
  if (cv::invert(jtj, cov, cv::DECOMP_SVD) == 0) return v;
  double far = 0;
  for (const auto& q : p) far = std::max(far, std::hypot(q[0] - th[0], q[1] - th[1]) / pitch);
  const double x = std::max(0.0, far - th[3]);
  v.drop = (th[4] * std::pow(x, 1.5) + th[5] * std::pow(x, 2.5)) / th[2];
  v.axis = {th[0], th[1]};
  v.axis_sigma = std::sqrt(std::max(0.0, 0.5 * (cov(0, 0) + cov(1, 1)) * s2));
  v.r0 = th[3] * pitch;
  v.r0_sigma = std::sqrt(std::max(0.0, cov(3, 3) * s2)) * pitch;
  v.a0 = th[2];
  // A fall-off well above the areas' noise, an axis it places to within a few pixels.
  v.found = v.drop > 0.01 && v.drop * th[2] > 10 * std::sqrt(s2) && v.axis_sigma < 5 && std::isfinite(v.axis_sigma);
  return v;
}

// Lenses cut by vignetting: beyond the cat's-eye radius (less a margin of three sigmas and a
// quarter pitch) where the radial model finds one; else (vignetting that is no radial fall-off)
// those whose areas fall short of the rest (vignetted_lenses). `found` receives the model.
std::vector<std::uint8_t> find_vignetted(const std::vector<std::array<int, 2>>& sites, const std::vector<LensFit>& fits,
                                         const std::vector<double>& area, const std::vector<std::uint8_t>& use,
                                         double pitch, Vignetting* found) {
  std::vector<std::array<double, 2>> p;
  std::vector<double> a;
  for (std::size_t k = 0; k < sites.size(); ++k) {
    if (!use[k] || !std::isfinite(area[k])) continue;
    p.push_back(fits[k].centre);
    a.push_back(area[k]);
  }
  const Vignetting v = fit_vignetting(p, a, pitch);
  if (found) *found = v;
  if (!v.found) return vignetted_lenses(sites, area, use);
  std::vector<std::uint8_t> out(sites.size(), 0);
  const double inner = v.r0 - 3 * v.r0_sigma - 0.25 * pitch;
  for (std::size_t k = 0; k < sites.size(); ++k) {
    out[k] = std::hypot(fits[k].centre[0] - v.axis[0], fits[k].centre[1] - v.axis[1]) > inner;
  }
  return out;
}

// The lattice the candidates sit on: its scale from the image itself (their nearest-neighbour
// distance), then neighbour statistics and a fit. InputError saying what was found and what to
// check when they are too few, too far from the camera file's pitch, or on no lattice.
// `trust_file`: take the camera file's pitch for the neighbour statistics and accept a lattice
// that holds a quarter of the candidates (overlapping micro-images add maxima between lenses).
RawLattice lattice_from_candidates(const Candidates& cand, const optics::CameraModel& camera, CentreSource kind,
                                   bool trust_file) {
  const std::string what = image_name(kind);
  const bool hex = camera.microlens().layout == optics::LensletLayout::hex;
  const double p0 = camera.spot_pitch_px();
  const long expected = expected_lenses(camera);
  auto levels = [&] {
    return " (smoothed image: background " + fmt(cand.background, 1) + ", bright level " + fmt(cand.bright, 1) +
           ", detection level " + fmt(cand.threshold, 1) + ")";
  };
  if (cand.points.size() < 10) {
    throw InputError(what + ": found " + count_str(long(cand.points.size())) + " " + things(kind) +
                     ", expected about " + count_str(expected) + " (one per microlens)" + levels() +
                     (kind == CentreSource::spots
                          ? ": is the target lit and the aperture stopped down? For a white image alone use "
                            "`--white` without `--calibration-image`"
                          : ": is this a white image through the microlens array (open aperture, evenly lit "
                            "target, not saturated)?"));
  }
  // 2. The lattice: its scale from the image itself, then neighbour statistics and a fit.
  const double seen = trust_file ? p0 : median_neighbour_distance(cand.points);
  if (!(std::abs(seen / p0 - 1) <= 0.35)) {
    throw InputError(what + ": its " + count_str(long(cand.points.size())) + " brightest " + things(kind) + " lie " +
                     fmt(seen, 2) + " px from their nearest neighbours, the camera file puts micro-images " +
                     fmt(p0, 2) +
                     " px apart (microlens.pitch_mm x (1 + f_l / s_i) / sensor.pixel_pitch_mm): "
                     "check those keys" +
                     (kind == CentreSource::spots ? "" : ", and that the image is in focus on the microlenses"));
  }
  RawLattice lat;
  try {
    lat = estimate_lattice(cand.points, hex, seen, things(kind));
  } catch (const InputError& e) {
    throw InputError(what + ": " + e.what());
  }
  std::vector<std::array<int, 2>> ij(cand.points.size());
  std::vector<double> wt(cand.points.size());
  int on_lattice = 0;
  for (int round = 0; round < 3; ++round) {
    on_lattice = 0;
    for (std::size_t k = 0; k < cand.points.size(); ++k) {
      ij[k] = lat.nearest(cand.points[k][0], cand.points[k][1]);
      const auto s = lat.site(ij[k][0], ij[k][1]);
      const bool near = std::hypot(cand.points[k][0] - s[0], cand.points[k][1] - s[1]) < 0.25 * lat.px;
      wt[k] = near ? 1.0 : 0.0;
      on_lattice += near;
    }
    refine_lattice(cand.points, ij, wt, lat);
  }
  if (on_lattice < std::max<long>(10, long(cand.points.size()) / (trust_file ? 4 : 2))) {
    throw InputError(what + ": of " + count_str(long(cand.points.size())) + " " + things(kind) + " only " +
                     count_str(on_lattice) + " lie within a quarter pitch of a " + (hex ? "hex" : "rect") +
                     " lattice of " + fmt(lat.px, 2) + " x " + fmt(lat.py, 2) +
                     " px: they do not form the camera file's lattice (check microlens.layout and pitch_mm" +
                     (kind == CentreSource::spots ? ")" : "; is this a white image through the microlens array?)") +
                     layout_hint(lat, camera));
  }
  return lat;
}

Measured measure_micro_images(const optics::CameraModel& camera, const ImageF& image, CentreSource kind) {
  const std::string what = image_name(kind);
  const bool hex = camera.microlens().layout == optics::LensletLayout::hex;
  const double p0 = camera.spot_pitch_px();
  const int w = image.width, h = image.height;
  Measured m;

  // 1. Rough centres: maxima of the smoothed image.
  // Smoothed at a fifth of the pitch each micro-image has one maximum; where neighbours overlap
  // the doubled light between them makes more, and a coarser smoothing (a third) is tried.
  Candidates cand;
  RawLattice lat;
  std::string first_error;
  // Last, the camera file's pitch for the neighbour statistics: maxima between overlapping
  // micro-images hide the image's own pitch, and measure_white then says they overlap.
  // Only a white can overlap; a lattice so found stands only if the white then shows the overlap
  // (Measured::doubt), else the first attempt's error is the answer.
  const std::array<std::pair<double, bool>, 3> attempts{{{0.2, false}, {0.35, false}, {0.2, true}}};
  bool found = false;
  for (const auto& [scale, trust_file] : attempts) {
    if (trust_file && kind != CentreSource::white) break;
    try {
      cand = find_candidates(image, p0, scale);
      lat = lattice_from_candidates(cand, camera, kind, trust_file);
      found = true;
      if (trust_file) m.doubt = first_error;
      break;
    } catch (const InputError& e) {
      if (first_error.empty()) first_error = e.what();
    }
  }
  if (!found) throw InputError(first_error);
  m.stats.threshold = cand.threshold;
  // 3. Hot pixels out, but not where a spot may fall in one pixel.
  ImageF clean = image;
  const double noise = pixel_noise(image);
  std::vector<std::array<double, 2>> keep;
  // Every site on the sensor, and one cell beyond its edge.
  const double margin = 0.5 * std::max(lat.px, lat.py);
  {
    const auto corners = {lat.coords(-margin, -margin), lat.coords(w + margin, -margin),
                          lat.coords(-margin, h + margin), lat.coords(w + margin, h + margin)};
    double amin = 1e300, amax = -1e300, bmin = 1e300, bmax = -1e300;
    for (const auto& c : corners) {
      amin = std::min(amin, c[0]);
      amax = std::max(amax, c[0]);
      bmin = std::min(bmin, c[1]);
      bmax = std::max(bmax, c[1]);
    }
    for (int j = int(std::floor(bmin)) - 1; j <= int(std::ceil(bmax)) + 1; ++j) {
      for (int i = int(std::floor(amin)) - 2; i <= int(std::ceil(amax)) + 2; ++i) {
        const auto s = lat.site(i, j);
        if (s[0] < -0.5 - margin || s[1] < -0.5 - margin || s[0] > w - 0.5 + margin || s[1] > h - 0.5 + margin)
          continue;
        m.sites.push_back({i, j});
      }
    }
  }
  // Stopped-down spots narrower than a pixel look like hot pixels: where the typical spot puts most
  // of its light in one pixel, pixels within two of a lattice site are left alone.
  if (kind == CentreSource::spots) {
    std::vector<double> ratio;
    for (const auto& q : cand.points) {
      int bx = int(std::lround(q[0])), by = int(std::lround(q[1]));
      if (bx < 2 || by < 2 || bx >= w - 2 || by >= h - 2) continue;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (image.at(bx + dx, by + dy) > image.at(bx, by)) bx += dx, by += dy, dx = dy = 2;
      double top = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (dx || dy) top = std::max(top, double(image.at(bx + dx, by + dy)) - cand.background);
      ratio.push_back((image.at(bx, by) - cand.background) / std::max(top, 1e-9));
    }
    if (median(ratio) > 3.0) {
      for (const auto& s : m.sites) keep.push_back(lat.site(s[0], s[1]));
    }
  }
  m.stats.hot_pixels = remove_hot_pixels(clean, cand.background, std::max(noise, 1e-6), 3.0, keep, 2.0);
  m.stats.noise_sigma = noise;

  // 4. Per-lens fits of the image's own mean micro-image, twice: the second with the noise model
  // and robust weights the first pass measured, on the refined lattice and template.
  const std::size_t n = m.sites.size();
  std::vector<LensFit> start(n);
  const double r0 = std::max(1.0, 0.15 * lat.px);
  for (std::size_t k = 0; k < n; ++k) {
    const auto s = lat.site(m.sites[k][0], m.sites[k][1]);
    double sum = 0;
    int cnt = 0;
    for (int y = int(std::floor(s[1] - r0)); y <= int(std::ceil(s[1] + r0)); ++y) {
      for (int x = int(std::floor(s[0] - r0)); x <= int(std::ceil(s[0] + r0)); ++x) {
        if (x < 0 || y < 0 || x >= w || y >= h || (x - s[0]) * (x - s[0]) + (y - s[1]) * (y - s[1]) > r0 * r0) continue;
        sum += clean.at(x, y);
        ++cnt;
      }
    }
    start[k].centre = s;
    start[k].background = cand.background;
    start[k].amplitude = cnt > 0 ? sum / cnt - cand.background : 0.0;
  }
  auto inside = [&](const std::array<double, 2>& c, double r) {
    return c[0] - r >= -0.5 && c[1] - r >= -0.5 && c[0] + r <= w - 0.5 && c[1] + r <= h - 0.5;
  };
  auto bright_whole = [&](const std::vector<LensFit>& f, double r, bool need_converged) {
    std::vector<double> amps;
    for (std::size_t k = 0; k < n; ++k) {
      if (inside(f[k].centre, r) && (!need_converged || f[k].converged)) amps.push_back(f[k].amplitude);
    }
    const double med = median(amps);
    std::vector<std::uint8_t> use(n, 0);
    for (std::size_t k = 0; k < n; ++k) {
      use[k] = inside(f[k].centre, r) && (!need_converged || f[k].converged) && f[k].amplitude > 0.3 * med;
    }
    return use;
  };
  // A white's micro-images may brighten towards one side (vignetting by the lens barrel, a
  // tilted target): a tilt across each image. It varies smoothly over the field, so it is fitted
  // lens by lens only to find that smooth field, and each lens's centre is then fitted with the
  // field's tilt held (a free tilt per small micro-image trades off against its centre).
  const bool white = kind == CentreSource::white;
  auto fit_round = [&](const std::vector<LensFit>& from, const MicroImageTemplate& t, const NoiseModel& nm,
                       const std::vector<std::uint8_t>& good, bool new_tilt) {
    if (!white || !new_tilt) return fit_lenses(clean, lat, m.sites, from, t, false, nm);
    std::vector<LensFit> held = from;
    smooth_tilt(fit_lenses(clean, lat, m.sites, from, t, true, nm), good, held);
    return fit_lenses(clean, lat, m.sites, held, t, false, nm);
  };
  std::vector<std::uint8_t> use = bright_whole(start, 0.75 * std::max(lat.px, lat.py), false);
  MicroImageTemplate shape(clean, lat, m.sites, start, use);
  std::vector<LensFit> fits = fit_round(start, shape, NoiseModel{}, use, false);
  double radius = std::max(1.5, shape.radius_at(0.05));
  std::vector<std::uint8_t> vignetted(n, 0);
  for (int round = 0; round < 2; ++round) {
    use = bright_whole(fits, radius, true);
    // Cat's-eye micro-images are no copies of the mean one: they neither shape it nor fix the lattice.
    if (white) {
      vignetted = find_vignetted(m.sites, fits, micro_image_areas(clean, lat, m.sites, fits), use, lat.px, nullptr);
      for (std::size_t k = 0; k < n; ++k) use[k] = use[k] && !vignetted[k];
    }
    const NoiseModel noise_model = estimate_noise_model(clean, lat, m.sites, fits, use, shape);
    // The lattice from the fitted centres; each lens keeps its index.
    std::vector<std::array<double, 2>> pts;
    std::vector<std::array<int, 2>> idx;
    std::vector<double> wts;
    for (std::size_t k = 0; k < n; ++k) {
      if (!use[k]) continue;
      pts.push_back(fits[k].centre);
      idx.push_back(m.sites[k]);
      wts.push_back(1.0);
    }
    refine_lattice(pts, idx, wts, lat);
    for (std::size_t k = 0; k < n; ++k) {
      if (!fits[k].converged) {
        fits[k].centre = lat.site(m.sites[k][0], m.sites[k][1]);
        fits[k].amplitude = std::max(fits[k].amplitude, start[k].amplitude);
        fits[k].background = start[k].background;
      }
    }
    shape = MicroImageTemplate(clean, lat, m.sites, fits, use);
    radius = std::max(1.5, shape.radius_at(0.05));
    fits = fit_round(fits, shape, noise_model, use, round == 0);
  }
  if (white) {
    vignetted = find_vignetted(m.sites, fits, micro_image_areas(clean, lat, m.sites, fits),
                               bright_whole(fits, radius, true), lat.px, &m.vignetting);
  }
  m.lattice = lat;
  m.fits = fits;
  m.image_radius_px = radius;
  m.vignetted = vignetted;

  // 5. Which sites hold a lens, whole or cut by the sensor edge, and which fits are flawed.
  m.whole.assign(n, 0);
  m.present.assign(n, 0);
  m.flawed.assign(n, 0);
  std::vector<double> amps, sigmas;
  for (std::size_t k = 0; k < n; ++k) {
    m.whole[k] = inside(lat.site(m.sites[k][0], m.sites[k][1]), radius + 0.5);
    if (m.whole[k] && fits[k].converged) {
      amps.push_back(fits[k].amplitude);
      sigmas.push_back(fits[k].sigma);
    }
  }
  const double amp_med = median(amps), sigma_med = median(sigmas);
  std::vector<double> backgrounds;
  for (std::size_t k = 0; k < n; ++k) {
    const LensFit& f = fits[k];
    if (!m.whole[k]) continue;
    const auto site = lat.site(m.sites[k][0], m.sites[k][1]);
    m.present[k] = f.converged && f.amplitude > 0.15 * amp_med && f.amplitude > 5 * f.amplitude_sigma;
    m.flawed[k] = m.present[k] && (f.outliers > 0.1 || f.sigma > 5 * sigma_med ||
                                   std::hypot(f.centre[0] - site[0], f.centre[1] - site[1]) > 0.3 * lat.px);
    if (m.present[k] && !m.flawed[k]) backgrounds.push_back(f.background);
  }
  const double b_med = backgrounds.empty() ? cand.background : median(backgrounds);
  // A lens cut by the sensor edge is there when its visible pixels would hold a tenth of a whole
  // micro-image's light, hold at least half of what the mean micro-image puts there (their mean
  // without the brightest 2 %: a hot pixel is no lens), and that light stands out of the noise.
  double whole_light = 0;
  for (double y = -radius; y <= radius; y += 1)
    for (double x = -radius; x <= radius; x += 1) whole_light += amp_med * shape.value(x, y);
  for (std::size_t k = 0; k < n; ++k) {
    if (m.whole[k]) continue;
    const auto site = lat.site(m.sites[k][0], m.sites[k][1]);
    std::vector<float> values;
    double expected = 0;
    for_each_cell_pixel(lat, m.sites[k][0], m.sites[k][1], w, h, [&](int x, int y) {
      values.push_back(clean.at(x, y));
      expected += amp_med * shape.value(x - site[0], y - site[1]);
    });
    if (values.size() < 4) continue;
    expected /= double(values.size());
    const std::size_t keep_n = values.size() - std::max<std::size_t>(1, values.size() / 50);
    std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(keep_n), values.end());
    double observed = 0;
    for (std::size_t q = 0; q < keep_n; ++q) observed += values[q] - b_med;
    observed /= double(keep_n);
    const double floor = std::max(noise, 1e-3 * amp_med);
    m.present[k] = expected * double(values.size()) > 0.1 * whole_light && observed > 0.5 * expected &&
                   expected > 5 * floor / std::sqrt(double(keep_n));
  }
  m.stats.background = b_med;

  // Hex: the array's first row must be an even row of the lattice (optics::Lattice shifts even
  // rows left, odd rows right). If it is odd, count rows from the one before: lens (i, j) becomes
  // (i - 1, j - 1) on even rows and (i, j - 1) on odd ones, the origin moving half a lens.
  if (hex) {
    int j0 = 1 << 30;
    for (std::size_t k = 0; k < n; ++k)
      if (m.present[k]) j0 = std::min(j0, m.sites[k][1]);
    if (j0 != (1 << 30) && (j0 & 1)) {
      for (auto& site : m.sites) {
        if (!(site[1] & 1)) site[0] -= 1;
        site[1] -= 1;
      }
      const auto origin = m.lattice.at(0.5, 1);
      m.lattice.ox = origin[0];
      m.lattice.oy = origin[1];
    }
  }
  return m;
}

// The evidence stage: lattice and distortion from the good lenses, the array's own departures
// against the measurements' scatter, and each lens's centre.
struct Model {
  LatticeModel model;
  std::vector<std::array<double, 2>> predicted;  // per site
  std::vector<double> weight;                    // per site: share of its own measurement in its centre
  double measurement_scatter = 0, array_scatter = 0;
};

Model choose_centres(Measured& m, const CalibrationOptions& options) {
  const std::size_t n = m.sites.size();
  Model out;
  double array_var = 0;
  std::vector<std::uint8_t> good(n, 0);
  for (std::size_t k = 0; k < n; ++k) good[k] = m.whole[k] && m.present[k] && !m.flawed[k] && !m.vignetted[k];
  for (int round = 0; round < 3; ++round) {
    std::vector<std::array<double, 2>> pts;
    std::vector<std::array<int, 2>> idx;
    std::vector<double> wts;
    for (std::size_t k = 0; k < n; ++k) {
      if (!good[k]) continue;
      pts.push_back(m.fits[k].centre);
      idx.push_back(m.sites[k]);
      wts.push_back(1.0 / (m.fits[k].sigma * m.fits[k].sigma + array_var + 1e-8));
    }
    if (pts.size() < 6) {
      throw InputError("too few whole micro-images measured (" + std::to_string(pts.size()) + ") to fit a lattice");
    }
    // A distortion is fitted only where the lenses it rests on span most of the array: a
    // polynomial fitted over a vignetting-free core would run wild towards the edges, where the
    // lattice (a lithographed array) holds.
    int extent[4] = {1 << 30, -(1 << 30), 1 << 30, -(1 << 30)}, all[4] = {1 << 30, -(1 << 30), 1 << 30, -(1 << 30)};
    for (std::size_t k = 0; k < n; ++k) {
      if (!m.present[k]) continue;
      int* e = good[k] ? extent : all;
      for (int* box : {e, all}) {
        box[0] = std::min(box[0], m.sites[k][0]);
        box[1] = std::max(box[1], m.sites[k][0]);
        box[2] = std::min(box[2], m.sites[k][1]);
        box[3] = std::max(box[3], m.sites[k][1]);
      }
    }
    const double span = std::min(double(extent[1] - extent[0] + 1) / double(all[1] - all[0] + 1),
                                 double(extent[3] - extent[2] + 1) / double(all[3] - all[2] + 1));
    out.model = fit_model(pts, idx, wts, m.lattice, span >= 0.8 ? options.max_distortion_degree : 0);
    // Residuals, the measurements' own scatter and what the array adds to it (robust, per axis).
    std::vector<double> res, var;
    for (std::size_t k = 0; k < n; ++k) {
      if (!good[k]) continue;
      const auto q = out.model.position(m.sites[k][0], m.sites[k][1]);
      res.push_back(std::abs(m.fits[k].centre[0] - q[0]));
      res.push_back(std::abs(m.fits[k].centre[1] - q[1]));
      var.push_back(m.fits[k].sigma * m.fits[k].sigma);
    }
    const double robust = 1.4826 * median(res);
    const double measurement = median(var);
    array_var = std::max(0.0, robust * robust - measurement);
    // A lens far off the model for its uncertainty is flawed (a second spot, a scratch).
    for (std::size_t k = 0; k < n; ++k) {
      if (!good[k]) continue;
      const auto q = out.model.position(m.sites[k][0], m.sites[k][1]);
      const double d = std::hypot(m.fits[k].centre[0] - q[0], m.fits[k].centre[1] - q[1]);
      const double s = std::sqrt(m.fits[k].sigma * m.fits[k].sigma + array_var);
      if (d > std::max(6 * s, 0.05)) {
        good[k] = 0;
        m.flawed[k] = 1;
      }
    }
  }
  double sum_var = 0;
  int count = 0;
  out.predicted.resize(n);
  out.weight.assign(n, 0.0);
  for (std::size_t k = 0; k < n; ++k) {
    out.predicted[k] = out.model.position(m.sites[k][0], m.sites[k][1]);
    if (!good[k]) continue;
    const double v = m.fits[k].sigma * m.fits[k].sigma;
    out.weight[k] = array_var / (array_var + v);
    sum_var += v;
    ++count;
  }
  out.measurement_scatter = std::sqrt(sum_var / std::max(count, 1));
  out.array_scatter = std::sqrt(array_var);
  return out;
}

Calibration assemble(const optics::CameraModel& camera, Measured& m, CentreSource kind,
                     const CalibrationOptions& options) {
  const optics::SensorSpec& sensor = camera.sensor();
  const std::size_t n = m.sites.size();
  const std::string what = image_name(kind);
  Calibration cal;
  cal.sensor = sensor;
  cal.image_distance_mm = camera.image_distance_mm();
  cal.microlens_focal_length_mm = camera.microlens().focal_length_mm;
  cal.microlens_image_diameter_px = camera.microlens_image_diameter_px();
  cal.source = kind;
  cal.image_stats = m.stats;
  cal.camera_count_x = camera.microlens().count_x;
  cal.camera_count_y = camera.microlens().count_y;
  cal.predicted_fill = camera.predicted_fill();
  cal.nominal_spot_pitch_px = camera.spot_pitch_px();

  // How many lenses were found against what the camera file leads one to expect.
  int found = 0, whole_found = 0;
  for (std::size_t k = 0; k < n; ++k) {
    found += m.present[k];
    whole_found += m.present[k] && m.whole[k];
  }
  cal.spots_found = found;
  const long expected = expected_lenses(camera);
  if (double(found) < options.min_found_fraction * double(expected)) {
    throw InputError(what + ": found " + count_str(found) + " " + things(kind) + ", expected about " +
                     count_str(expected) + " (one per microlens; " + count_str(whole_found) +
                     " whole, on a lattice of " + fmt(m.lattice.px, 2) + " x " + fmt(m.lattice.py, 2) +
                     " px): is the whole sensor lit" +
                     (kind == CentreSource::spots ? ", and the stopped-down spots bright enough?"
                                                  : ", and is this a white image through the microlens array?") +
                     (camera.counts_given() ? " The camera file's microlens.count_x/count_y say how many lenses "
                                              "the array has; remove them if the sensor shows fewer."
                                            : ""));
  }

  // The pitch the image shows against the camera file's.
  const double p0 = camera.spot_pitch_px();
  const double row0 = p0 * camera.row_pitch_mm() / camera.microlens().pitch_mm;
  const Model chosen = choose_centres(m, options);
  const RawLattice& lat = chosen.model.lattice;
  cal.pitch_ratio = lat.px / p0;
  if (std::abs(lat.px / p0 - 1) > options.pitch_tolerance || std::abs(lat.py / row0 - 1) > options.pitch_tolerance) {
    throw InputError(what + ": the " + things(kind) + " lie on a lattice of " + fmt(lat.px) + " x " + fmt(lat.py) +
                     " px, more than " + fmt(100 * options.pitch_tolerance, 0) + " % from the camera file's " +
                     fmt(p0) + " x " + fmt(row0) +
                     " px (microlens.pitch_mm x (1 + f_l / s_i) / sensor.pixel_pitch_mm): check microlens.pitch_mm, "
                     "sensor.pixel_pitch_mm and microlens.focal_length_mm" +
                     layout_hint(lat, camera));
  }

  // The array: the sites holding a lens, as a block of whole rows and columns (hex: starting on
  // an even row, so that the row shift keeps its sense); at least the camera file's counts when
  // they fit on the sensor, placed nearest the optical axis.
  int i0 = 1 << 30, i1 = -(1 << 30), j0 = 1 << 30, j1 = -(1 << 30);
  for (std::size_t k = 0; k < n; ++k) {
    if (!m.present[k]) continue;
    i0 = std::min(i0, m.sites[k][0]);
    i1 = std::max(i1, m.sites[k][0]);
    j0 = std::min(j0, m.sites[k][1]);
    j1 = std::max(j1, m.sites[k][1]);
  }
  if (lat.hex && (j0 & 1)) --j0;
  int nx = i1 - i0 + 1, ny = j1 - j0 + 1;
  if (camera.counts_given()) {
    const int cx = camera.microlens().count_x, cy = camera.microlens().count_y;
    const bool fits = cx == camera.nominal_count_x() && cy == camera.nominal_count_y();
    if (fits && nx <= cx && ny <= cy) {
      // Place the camera file's array over the lenses found, nearest the optical axis.
      double best = 1e300;
      int bi = i0, bj = j0;
      for (int jj = j1 - cy + 1; jj <= j0; ++jj) {
        if (lat.hex && (jj & 1)) continue;
        for (int ii = i1 - cx + 1; ii <= i0; ++ii) {
          const auto c = lat.at(ii + 0.5 * (cx - 1) + (lat.hex ? 0.25 : 0.0), jj + 0.5 * (cy - 1));
          const double d =
              std::hypot(optics::column_to_sensor_mm(sensor, c[0]), optics::row_to_sensor_mm(sensor, c[1]));
          if (d < best) {
            best = d;
            bi = ii;
            bj = jj;
          }
        }
      }
      if (best < 1e300) {
        i0 = bi;
        j0 = bj;
        nx = cx;
        ny = cy;
      }
    } else if (fits) {
      cal.notes.push_back("the sensor shows " + std::to_string(nx) + " x " + std::to_string(ny) +
                          " lenses, more than the camera file's count_x x count_y = " + std::to_string(cx) + " x " +
                          std::to_string(cy) +
                          ": the calibration keeps all of them (the counts are a minimum; "
                          "remove them or write the array's real counts)");
    }
  }

  // Lattice in the camera's frame (mm from the optical axis), and every lens of the array.
  const double pp = sensor.pixel_pitch_mm;
  const auto centre = lat.at(i0 + 0.5 * (nx - 1) + (lat.hex ? 0.25 : 0.0), j0 + 0.5 * (ny - 1));
  cal.spot_lattice.layout = camera.microlens().layout;
  cal.spot_lattice.count_x = nx;
  cal.spot_lattice.count_y = ny;
  cal.spot_lattice.pitch_x_mm = lat.px * pp;
  cal.spot_lattice.pitch_y_mm = lat.py * pp;
  cal.spot_lattice.rotation_rad = lat.rotation;
  cal.spot_lattice.offset_x_mm = optics::column_to_sensor_mm(sensor, centre[0]);
  cal.spot_lattice.offset_y_mm = optics::row_to_sensor_mm(sensor, centre[1]);
  cal.distortion_degree = chosen.model.degree;
  cal.measurement_scatter_px = chosen.measurement_scatter;
  cal.array_scatter_px = chosen.array_scatter;

  const std::size_t nl = std::size_t(nx) * std::size_t(ny);
  const double nan = std::nan("");
  cal.spots_px.resize(nl);
  cal.status.assign(nl, LensStatus::missing);
  cal.residuals_px.assign(nl, {0.0, 0.0});
  cal.measured_px.assign(nl, {nan, nan});
  cal.uncertainty_px.assign(nl, nan);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) cal.spots_px[std::size_t(j) * nx + i] = chosen.model.position(i0 + i, j0 + j);
  }
  double sum2 = 0;
  int residuals = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const int i = m.sites[k][0] - i0, j = m.sites[k][1] - j0;
    if (i < 0 || j < 0 || i >= nx || j >= ny || !m.present[k]) continue;
    const std::size_t id = std::size_t(j) * nx + i;
    const LensFit& f = m.fits[k];
    if (f.converged) {
      cal.measured_px[id] = f.centre;
      cal.uncertainty_px[id] = f.sigma;
    }
    if (!m.whole[k]) {
      cal.status[id] = LensStatus::partial;
      ++cal.lenses_partial;
      continue;
    }
    const std::array<double, 2> r{f.centre[0] - chosen.predicted[k][0], f.centre[1] - chosen.predicted[k][1]};
    if (m.flawed[k] || !f.converged) {
      cal.status[id] = LensStatus::rejected;
      if (f.converged) cal.residuals_px[id] = r;
      ++cal.lenses_rejected;
      continue;
    }
    // A vignetted lens's own centre is pulled by its cat's eye: the model's is the better one.
    const double wgt = m.vignetted[k] ? 0.0 : chosen.weight[k];
    cal.lenses_vignetted += m.vignetted[k];
    cal.spots_px[id] = {chosen.predicted[k][0] + wgt * r[0], chosen.predicted[k][1] + wgt * r[1]};
    cal.residuals_px[id] = r;
    cal.status[id] = wgt >= 0.5 ? LensStatus::measured : LensStatus::lattice;
    (wgt >= 0.5 ? cal.lenses_measured : cal.lenses_lattice) += 1;
    sum2 += r[0] * r[0] + r[1] * r[1];
    cal.max_residual_px = std::max(cal.max_residual_px, std::hypot(r[0], r[1]));
    ++residuals;
  }
  cal.rms_residual_px = residuals > 0 ? std::sqrt(sum2 / residuals) : 0.0;

  // The pitch: a disagreement with the camera file is applied as a lens pitch (the lens centres
  // follow the spots), and said.
  const double ratio = cal.pitch_ratio;
  if (std::abs(ratio - 1) > 1e-3) {
    const double k_file = camera.microlens().focal_length_mm / camera.image_distance_mm();
    const double k_if_pitch_exact = ratio * (1 + k_file) - 1;
    std::string alternative;
    if (k_if_pitch_exact > 0) {
      alternative = " If the array's pitch is exact, the microlens-to-sensor distance is " +
                    fmt(k_if_pitch_exact * camera.image_distance_mm(), 4) + " mm rather than the camera file's " +
                    fmt(camera.microlens().focal_length_mm, 4) + " mm (or s_i is " +
                    fmt(camera.microlens().focal_length_mm / k_if_pitch_exact, 2) + " mm, not " +
                    fmt(camera.image_distance_mm(), 2) +
                    "): set microlens.focal_length_mm (or main_lens.magnification) and calibrate again.";
    }
    cal.notes.push_back("the micro-images are " + fmt(lat.px, 3) + " px apart, " + fmt(100 * std::abs(ratio - 1), 2) +
                        " % " + (ratio > 1 ? "more" : "less") + " than the camera file's " + fmt(p0, 3) +
                        " px: the lens centres follow the measurement (lens pitch " +
                        fmt(camera.microlens().pitch_mm * ratio, 5) + " mm instead of " +
                        fmt(camera.microlens().pitch_mm, 5) + " mm) in calibration, refocusing and reconstruction." +
                        alternative);
  }
  if (cal.lenses_vignetted > 0) {
    const int whole = cal.lenses_measured + cal.lenses_lattice + cal.lenses_rejected;
    const int core = whole - cal.lenses_vignetted - cal.lenses_rejected;
    cal.notes.push_back(std::to_string(cal.lenses_vignetted) +
                        " lenses show cat's-eye (vignetted) micro-images, passing less light for their brightness: "
                        "centred on the fitted lattice, which the " +
                        std::to_string(core) + " unvignetted ones fix" +
                        (core < whole / 4 ? std::string(". So few lenses reach far only if the array is regular: "
                                                        "a stopped-down calibration image (--calibration-image), "
                                                        "which the barrel does not cut, fixes the edges better")
                                          : std::string()));
  }
  if (cal.lenses_partial > 0) {
    cal.notes.push_back(std::to_string(cal.lenses_partial) +
                        " lenses are cut by the sensor edge: flagged partial, centred on the fitted lattice");
  }
  return cal;
}

// The calibration's spot lattice as a RawLattice with lens (0, 0) at the array's lens (0, 0).
RawLattice raw_lattice_of(const Calibration& cal) {
  RawLattice lat;
  const optics::Lattice& l = cal.spot_lattice;
  const double pp = cal.sensor.pixel_pitch_mm;
  lat.hex = l.layout == optics::LensletLayout::hex;
  lat.px = l.pitch_x_mm / pp;
  lat.py = l.pitch_y_mm / pp;
  lat.rotation = l.rotation_rad;
  const auto first = l.position(0, 0);
  lat.ox = optics::sensor_mm_to_column(cal.sensor, first[0]);
  lat.oy = optics::sensor_mm_to_row(cal.sensor, first[1]);
  return lat;
}

// Fits L = c0 + c1 r^2 + c2 r^4, r = |p - A|, to per-lens levels: the centre A of a radial fall-off.
// Returns false when the fall-off is too weak to place its centre.
bool radial_centre(const std::vector<std::array<double, 2>>& p, const std::vector<double>& level,
                   std::array<double, 2> a0, double diagonal, std::array<double, 2>& centre, double& sigma) {
  if (p.size() < 20) return false;
  double th[5] = {a0[0], a0[1], 0, 0, 0};
  {
    double mean = 0;
    for (double v : level) mean += v;
    th[2] = mean / double(level.size());
  }
  const double scale = 0.5 * diagonal;  // r in units of the half diagonal
  cv::Matx<double, 5, 5> jtj;
  double s2 = 0;
  for (int it = 0; it < 30; ++it) {
    jtj = cv::Matx<double, 5, 5>::zeros();
    cv::Vec<double, 5> jtr = cv::Vec<double, 5>::all(0);
    double chi2 = 0;
    for (std::size_t k = 0; k < p.size(); ++k) {
      const double dx = (p[k][0] - th[0]) / scale, dy = (p[k][1] - th[1]) / scale;
      const double r2 = dx * dx + dy * dy;
      const double model = th[2] + th[3] * r2 + th[4] * r2 * r2;
      const double res = level[k] - model;
      chi2 += res * res;
      const double dm_dr2 = th[3] + 2 * th[4] * r2;
      const double j[5] = {dm_dr2 * -2 * dx / scale, dm_dr2 * -2 * dy / scale, 1, r2, r2 * r2};
      for (int a = 0; a < 5; ++a) {
        jtr[a] += j[a] * res;
        for (int b = 0; b < 5; ++b) jtj(a, b) += j[a] * j[b];
      }
    }
    s2 = chi2 / double(p.size() - 5);
    cv::Vec<double, 5> step;
    cv::Matx<double, 5, 5> damped = jtj;
    for (int a = 0; a < 5; ++a) damped(a, a) *= 1.0 + 1e-6;
    if (!cv::solve(damped, jtr, step, cv::DECOMP_CHOLESKY)) return false;
    const double move = std::hypot(step[0], step[1]);
    const double shrink = move > 0.1 * diagonal ? 0.1 * diagonal / move : 1.0;
    for (int a = 0; a < 5; ++a) th[a] += shrink * step[a];
    if (move < 1e-4) break;
  }
  cv::Matx<double, 5, 5> cov;
  if (cv::invert(jtj, cov, cv::DECOMP_CHOLESKY) == 0) return false;
  sigma = std::sqrt(std::max(0.0, 0.5 * (cov(0, 0) + cov(1, 1)) * s2));
  centre = {th[0], th[1]};
  // The fall-off across the lenses, against the noise of one level.
  double lo = 1e300, hi = -1e300;
  for (const auto& q : p) {
    const double dx = (q[0] - th[0]) / scale, dy = (q[1] - th[1]) / scale;
    const double r2 = dx * dx + dy * dy;
    const double v = th[2] + th[3] * r2 + th[4] * r2 * r2;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  const double falloff = (hi - lo) / std::max(std::abs(th[2]), 1e-12);
  return falloff > 0.02 && hi - lo > 10 * std::sqrt(s2) && sigma < 0.02 * diagonal && std::isfinite(sigma);
}

}  // namespace

namespace {

// A white's calibration from its micro-images, then the white's evidence. Where the lattice
// needed the camera file's pitch (Measured::doubt), only overlapping micro-images (refused by
// measure_white) explain the image; anything else, the first error stands.
Calibration assemble_white(const optics::CameraModel& camera, Measured& m, const ImageF& white,
                           const CalibrationOptions& options, std::optional<double> black_level) {
  Calibration cal;
  try {
    cal = assemble(camera, m, CentreSource::white, options);
  } catch (const InputError&) {
    if (!m.doubt.empty()) throw InputError(m.doubt);
    throw;
  }
  measure_white(cal, white, options, black_level);
  if (!m.doubt.empty()) throw InputError(m.doubt);
  return cal;
}

}  // namespace

Calibration calibrate(const optics::CameraModel& camera, const ImageF& image, const CalibrationOptions& options) {
  check_image(camera.sensor(), image, "calibration image");
  Measured m = measure_micro_images(camera, image, CentreSource::spots);
  return assemble(camera, m, CentreSource::spots, options);
}

Calibration calibrate_from_white(const optics::CameraModel& camera, const ImageF& white,
                                 const CalibrationOptions& options) {
  check_image(camera.sensor(), white, "white image");
  Measured m = measure_micro_images(camera, white, CentreSource::white);
  Calibration cal = assemble_white(camera, m, white, options, std::nullopt);
  return cal;
}

namespace {

// Moves the calibration's frame to an optical axis at `axis_px`; every spot stays where it was measured.
void set_optical_axis(Calibration& cal, const std::array<double, 2>& axis_px) {
  const std::array<double, 2> offset_px{optics::sensor_mm_to_column(cal.sensor, cal.spot_lattice.offset_x_mm),
                                        optics::sensor_mm_to_row(cal.sensor, cal.spot_lattice.offset_y_mm)};
  cal.sensor.optical_axis_px = axis_px;
  cal.spot_lattice.offset_x_mm = optics::column_to_sensor_mm(cal.sensor, offset_px[0]);
  cal.spot_lattice.offset_y_mm = optics::row_to_sensor_mm(cal.sensor, offset_px[1]);
}

}  // namespace

void measure_white(Calibration& cal, const ImageF& white, const CalibrationOptions& options,
                   std::optional<double> black_level) {
  check_image(cal.sensor, white, "white image");
  const RawLattice lat = raw_lattice_of(cal);
  const int nx = cal.spot_lattice.count_x, ny = cal.spot_lattice.count_y;
  const double pitch = lat.px;
  // The white's own mean micro-image around the calibrated centres of the lenses measured whole.
  std::vector<std::array<int, 2>> sites;
  std::vector<LensFit> lenses;
  std::vector<std::uint8_t> use;
  std::vector<double> dark;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const std::size_t id = std::size_t(j) * nx + i;
      const LensStatus s = cal.status[id];
      if (s != LensStatus::measured && s != LensStatus::lattice) continue;
      LensFit f;
      f.centre = cal.spots_px[id];
      double lo = 1e300, sum = 0;
      int cnt = 0;
      for_each_cell_pixel(lat, i, j, white.width, white.height, [&](int x, int y) {
        const double v = white.at(x, y);
        lo = std::min(lo, v);
        if (std::hypot(x - f.centre[0], y - f.centre[1]) <= 0.15 * pitch) {
          sum += v;
          ++cnt;
        }
      });
      if (cnt == 0) continue;
      f.background = lo;
      f.amplitude = sum / cnt - lo;
      sites.push_back({i, j});
      lenses.push_back(f);
      use.push_back(f.amplitude > 0);
      dark.push_back(lo);
    }
  }
  if (sites.size() < 10) return;
  const MicroImageTemplate shape(white, lat, sites, lenses, use);
  const std::vector<LensFit> fits = fit_lenses(white, lat, sites, lenses, shape, false, NoiseModel{});
  std::vector<double> backgrounds;
  std::vector<std::array<double, 2>> where;
  std::vector<double> level;
  for (std::size_t k = 0; k < fits.size(); ++k) {
    if (!fits[k].converged) continue;
    backgrounds.push_back(fits[k].background);
    where.push_back(lenses[k].centre);
    level.push_back(fits[k].amplitude);
  }
  // The black level: given (a dark frame was subtracted), else the level between micro-images.
  cal.white_black_level = black_level ? *black_level : backgrounds.empty() ? median(dark) : median(backgrounds);

  // Fill from the light each lens passes: a lens's cell holds its whole micro-image's light
  // (what it spills into its neighbours' cells they spill into its own), so the light over the
  // centre's level is the micro-image's area, whatever its blur or overlap: diameter
  // 2 sqrt(area / pi). A micro-image that dims towards its rim reads a little small.
  // Cat's-eye vignetting (micro-image areas falling off radially): its centre is the optical
  // axis, whatever the target's lighting, and only the lenses inside it show the whole aperture.
  const std::vector<double> areas = micro_image_areas(white, lat, sites, fits);
  std::vector<std::array<double, 2>> at;
  std::vector<double> area_at;
  for (std::size_t k = 0; k < sites.size(); ++k) {
    if (!std::isfinite(areas[k])) continue;
    at.push_back(fits[k].centre);
    area_at.push_back(areas[k]);
  }
  const Vignetting vignetting = fit_vignetting(at, area_at, pitch);
  std::vector<double> diameters;
  for (std::size_t k = 0; k < sites.size(); ++k) {
    if (vignetting.found && std::hypot(lenses[k].centre[0] - vignetting.axis[0],
                                       lenses[k].centre[1] - vignetting.axis[1]) > vignetting.r0) {
      continue;
    }
    double sum = 0, centre = 0;
    int cells = 0, central = 0;
    const auto& c = lenses[k].centre;
    bool cut = false;
    for_each_cell_pixel(lat, sites[k][0], sites[k][1], white.width, white.height, [&](int x, int y) {
      const double v = white.at(x, y) - cal.white_black_level;
      sum += v;
      ++cells;
      if (std::hypot(x - c[0], y - c[1]) <= 0.2 * pitch) {
        centre += v;
        ++central;
      }
      cut = cut || x == 0 || y == 0 || x == white.width - 1 || y == white.height - 1;
    });
    if (cut || central == 0 || !(centre > 0)) continue;
    diameters.push_back(2 * std::sqrt(sum / (centre / central) / std::numbers::pi));
  }
  if (diameters.empty()) return;
  const double diameter = median(diameters);
  cal.fill = diameter / pitch;
  const double predicted = cal.predicted_fill;
  if (cal.fill > options.max_fill) {
    throw InputError("white image: the micro-images overlap: they are " + fmt(diameter, 2) + " px across (from the " +
                     "light each lens passes), " + fmt(100 * cal.fill, 1) + " % of the " + fmt(pitch, 2) +
                     " px pitch, so neighbours share pixels whose aperture point is ambiguous (the camera file's "
                     "f-number predicts " +
                     fmt(100 * predicted, 1) + " %): stop the main lens down by " + fmt(cal.fill, 2) +
                     " x in f-number or more and take the white and the frames again");
  }
  if (predicted > 0 && std::abs(cal.fill / predicted - 1) > 0.05) {
    cal.notes.push_back("the white's micro-images fill " + fmt(100 * cal.fill, 1) + " % of the pitch (" +
                        fmt(diameter, 2) + " px across), the camera file's main_lens.f_number predicts " +
                        fmt(100 * predicted, 1) + " %: an f-number of " + fmt(predicted / cal.fill, 3) +
                        " x the camera file's gives the measured fill; set main_lens.f_number to it so that the "
                        "reconstruction's aperture matches the images" +
                        (black_level ? "" : " (no dark frame: the fill assumes the black level between the images)"));
  }

  // The optical axis: the centre of the cat's-eye fall-off, else of the white's brightness
  // fall-off (natural vignetting, which an unevenly lit target biases), where it has one.
  const double diagonal = std::hypot(double(white.width), double(white.height));
  std::array<double, 2> centre{};
  double sigma = 0;
  const std::array<double, 2> frame{optics::sensor_mm_to_column(cal.sensor, 0.0),
                                    optics::sensor_mm_to_row(cal.sensor, 0.0)};
  bool placed = vignetting.found;
  if (placed) {
    centre = vignetting.axis;
    sigma = vignetting.axis_sigma;
  } else {
    placed = radial_centre(where, level, frame, diagonal, centre, sigma);
  }
  if (placed) {
    cal.measured_axis_px = centre;
    cal.measured_axis_sigma_px = sigma;
    const double off = std::hypot(centre[0] - frame[0], centre[1] - frame[1]);
    if (vignetting.found && !cal.sensor.optical_axis_px) {
      // The cat's eye is geometry (the lens barrel cutting the cones), not lighting: where the
      // camera file gives no axis, the calibration's frame becomes the measured one.
      set_optical_axis(cal, centre);
      cal.axis_measured = true;
      cal.notes.push_back(
          "the optical axis: not in the camera file; measured from the micro-images' cat's-eye "
          "vignetting at column " +
          fmt(centre[0], 1) + ", row " + fmt(centre[1], 1) + " (+-" + fmt(sigma, 1) + " px, " + fmt(off, 1) +
          " px from the sensor centre) and used by refocus and reconstruction with this "
          "calibration (`optical_axis_px` in the camera file's sensor section overrides it)");
    } else if (off > std::max(3 * sigma, 2.0)) {
      cal.notes.push_back(
          std::string(vignetting.found ? "the micro-images' cat's-eye vignetting" : "the white's fall-off") +
          " is centred at column " + fmt(centre[0], 1) + ", row " + fmt(centre[1], 1) + " (+-" + fmt(sigma, 1) +
          " px), " + fmt(off, 1) + " px from the optical axis used (" +
          (cal.sensor.optical_axis_px ? std::string("sensor.optical_axis_px") : std::string("the sensor centre")) +
          (vignetting.found ? std::string("): that is where the optical axis meets the sensor; ")
                            : std::string("): if the white target was evenly lit, that is where the "
                                          "optical axis meets the sensor (an unevenly lit target moves it, so "
                                          "it is not applied); ")) +
          "add `optical_axis_px: [" + fmt(centre[0], 1) + ", " + fmt(centre[1], 1) +
          "]` to the camera file's sensor section and calibrate again");
    }
  } else if (!cal.sensor.optical_axis_px) {
    cal.notes.push_back(
        "the optical axis: not given in the camera file, and the white is too flat to place it "
        "(its fall-off centre); the sensor centre is used (sensor.optical_axis_px sets it)");
  }
}

Calibration calibrate_camera(const optics::CameraModel& camera, const CalibrationFrames& frames,
                             const CalibrationOptions& options, double* light_outside_fraction) {
  const optics::SensorSpec& sensor = camera.sensor();
  if (frames.white.empty()) throw std::logic_error("calibrate_camera: a white image is required");
  auto minus_dark = [&](const ImageF& image, const std::string& what) {
    check_image(sensor, image, what);
    if (frames.dark.empty()) return image;
    ImageF out = image;
    for (std::size_t k = 0; k < out.size(); ++k) out.pixels[k] -= frames.dark.pixels[k];
    return out;
  };
  if (!frames.dark.empty()) check_image(sensor, frames.dark, "dark image");
  const ImageF white = minus_dark(frames.white, "white image");
  Calibration cal;
  double dark_level = 0;
  if (!frames.calibration.empty()) {
    cal = calibrate(camera, minus_dark(frames.calibration, "calibration image"), options);
    measure_white(cal, white, options, frames.dark.empty() ? std::nullopt : std::optional<double>(0.0));
    // Without a dark frame the calibration image's background (between its spots) is the black level.
    dark_level = frames.dark.empty() ? cal.image_stats.background : 0.0;
  } else {
    check_image(sensor, white, "white image");
    Measured m = measure_micro_images(camera, white, CentreSource::white);
    cal = assemble_white(camera, m, white, options, frames.dark.empty() ? std::nullopt : std::optional<double>(0.0));

    if (frames.dark.empty()) {
      dark_level = cal.white_black_level;
      cal.notes.push_back("no dark frame: the white's black level is taken from between its micro-images (" +
                          fmt(dark_level, 2) +
                          " counts); `--dark` with frames taken with the lens capped is "
                          "more exact");
    }
  }
  cal.calibration_frames = frames.calibration.empty() ? 0 : std::max(1, frames.calibration_frames);
  cal.white_frames = std::max(1, frames.white_frames);
  cal.dark_frames = frames.dark.empty() ? 0 : std::max(1, frames.dark_frames);
  cal.white_correction = make_white_correction(cal, white, dark_level, light_outside_fraction);
  return cal;
}

std::string describe(const Calibration& cal) {
  std::ostringstream o;
  const double pp = cal.sensor.pixel_pitch_mm;
  int missing = 0;
  for (LensStatus s : cal.status) missing += s == LensStatus::missing;
  const double deg = 180 / std::numbers::pi;
  o << "  centres from       "
    << (cal.source == CentreSource::spots ? "the calibration (stopped-down) image" : "the white image") << "\n"
    << "  lenses             " << cal.spot_lattice.count_x << " x " << cal.spot_lattice.count_y << " "
    << optics::to_string(cal.spot_lattice.layout) << " (" << cal.spots_found
    << " found on the sensor): " << cal.lenses_measured << " measured, " << cal.lenses_lattice
    << " on the fitted lattice (measurement scatter larger than the array's), " << cal.lenses_rejected
    << " rejected (dust, flaws), " << cal.lenses_partial << " cut by the sensor edge, " << missing
    << " not on the sensor\n"
    << "  spot pitch         " << fmt(cal.spot_lattice.pitch_x_mm / pp, 4) << " x "
    << fmt(cal.spot_lattice.pitch_y_mm / pp, 4) << " px (camera file " << fmt(cal.nominal_spot_pitch_px, 4)
    << " px along rows; measured / file " << fmt(cal.pitch_ratio, 5) << ")\n"
    << "  rotation           " << fmt(cal.spot_lattice.rotation_rad * deg, 4) << " deg\n"
    << "  array centre       " << fmt(cal.spot_lattice.offset_x_mm / pp, 2) << ", "
    << fmt(cal.spot_lattice.offset_y_mm / pp, 2) << " px from the optical axis (column "
    << fmt(optics::sensor_mm_to_column(cal.sensor, 0.0), 2) << ", row "
    << fmt(optics::sensor_mm_to_row(cal.sensor, 0.0), 2)
    << (cal.axis_measured            ? ", measured: cat's eye"
        : cal.sensor.optical_axis_px ? ", camera file"
                                     : ", sensor centre")
    << ")\n"
    << "  model              "
    << (cal.distortion_degree == 0 ? std::string("lattice")
                                   : "lattice + degree-" + std::to_string(cal.distortion_degree) + " distortion")
    << "; measured - model " << fmt(cal.rms_residual_px, 4) << " px rms, " << fmt(cal.max_residual_px, 3) << " px max\n"
    << "  per lens           measurement scatter " << fmt(cal.measurement_scatter_px, 4)
    << " px rms; the array departs from its model by " << fmt(cal.array_scatter_px, 4) << " px rms beyond it\n";
  if (std::isfinite(cal.fill)) {
    o << "  micro-image fill   " << fmt(100 * cal.fill, 1) << " % of the pitch measured, "
      << fmt(100 * cal.predicted_fill, 1) << " % predicted from the camera file\n";
  }
  if (std::isfinite(cal.measured_axis_px[0])) {
    o << "  white's fall-off   centred at column " << fmt(cal.measured_axis_px[0], 1) << ", row "
      << fmt(cal.measured_axis_px[1], 1) << " (+-" << fmt(cal.measured_axis_sigma_px, 1) << " px)\n";
  }
  if (cal.white_frames > 0) {
    o << "  frames             " << cal.calibration_frames << " calibration, " << cal.white_frames << " white, "
      << cal.dark_frames << " dark\n";
  }
  for (const std::string& n : cal.notes) o << "  note: " << n << "\n";
  return o.str();
}

optics::MicrolensArray Calibration::microlens_array() const {
  const double s_i = image_distance_mm, f_l = microlens_focal_length_mm;
  optics::MicrolensArray array;
  array.lattice = spot_lattice;
  array.lattice.pitch_x_mm = optics::spot_to_lens_centre_mm(spot_lattice.pitch_x_mm, s_i, f_l);
  array.lattice.pitch_y_mm = optics::spot_to_lens_centre_mm(spot_lattice.pitch_y_mm, s_i, f_l);
  array.lattice.offset_x_mm = optics::spot_to_lens_centre_mm(spot_lattice.offset_x_mm, s_i, f_l);
  array.lattice.offset_y_mm = optics::spot_to_lens_centre_mm(spot_lattice.offset_y_mm, s_i, f_l);
  array.centres_mm.reserve(spots_px.size());
  for (const auto& q : spots_px) {
    array.centres_mm.push_back({optics::spot_to_lens_centre_mm(optics::column_to_sensor_mm(sensor, q[0]), s_i, f_l),
                                optics::spot_to_lens_centre_mm(optics::row_to_sensor_mm(sensor, q[1]), s_i, f_l)});
  }
  return array;
}

namespace {

// The lens a pixel belongs to: the nearest measured spot among the lattice neighbours of the
// pixel's nearest lattice site (spots depart from the lattice by a fraction of a pixel).
class LensFinder {
 public:
  LensFinder(const optics::SensorSpec& sensor, const optics::Lattice& spot_lattice,
             const std::vector<std::array<double, 2>>& spots_px)
      : spots_(spots_px), cx_(0.5 * sensor.width_px - 0.5), cy_(0.5 * sensor.height_px - 0.5) {
    const double pp = sensor.pixel_pitch_mm;
    lat_.hex = spot_lattice.layout == optics::LensletLayout::hex;
    lat_.nx = spot_lattice.count_x;
    lat_.ny = spot_lattice.count_y;
    lat_.px = spot_lattice.pitch_x_mm / pp;
    lat_.py = spot_lattice.pitch_y_mm / pp;
    lat_.th = spot_lattice.rotation_rad;
    lat_.ox = spot_lattice.offset_x_mm / pp;
    lat_.oy = spot_lattice.offset_y_mm / pp;
    c_ = std::cos(lat_.th);
    s_ = std::sin(lat_.th);
    // Within the inscribed circle of its Voronoi cell, shrunk by the largest departure of a spot
    // from the lattice, a pixel's lattice site is certainly its lens: no search needed (~3/4 of
    // all pixels).
    double departure = 0;
    for (int j = 0; j < lat_.ny; ++j) {
      for (int i = 0; i < lat_.nx; ++i) {
        const auto q = lat_.position(i, j);
        const auto& m = spots_[std::size_t(j) * lat_.nx + i];
        departure = std::max(departure, std::hypot(m[0] - cx_ - q[0], m[1] - cy_ - q[1]));
      }
    }
    const double inscribed =
        0.5 * (lat_.hex ? std::min(lat_.px, std::hypot(0.5 * lat_.px, lat_.py)) : std::min(lat_.px, lat_.py));
    const double sure = std::max(0.0, inscribed - departure - 0.01);
    sure2_ = sure * sure;
  }

  // Lens index j * count_x + i, or -1 beyond the array's edge.
  int lens_at(int x, int y) const {
    const double dx = x - cx_ - lat_.ox, dy = y - cy_ - lat_.oy;
    const double b = (s_ * dx + c_ * dy) / lat_.py + 0.5 * (lat_.ny - 1);
    const int j0 = int(std::floor(b + 0.5));
    const double a = (c_ * dx - s_ * dy) / lat_.px + 0.5 * (lat_.nx - 1) - lat_.shift(j0);
    const int i0 = int(std::floor(a + 0.5));
    if (i0 < 0 || j0 < 0 || i0 >= lat_.nx || j0 >= lat_.ny) return -1;
    const double ea = (a - i0) * lat_.px, eb = (b - j0) * lat_.py;
    if (ea * ea + eb * eb < sure2_) return j0 * lat_.nx + i0;
    double best = 1e300;
    int who = -1;
    for (int j = std::max(0, j0 - 1); j <= std::min(lat_.ny - 1, j0 + 1); ++j) {
      const std::array<double, 2>* row = &spots_[std::size_t(j) * lat_.nx];
      for (int i = std::max(0, i0 - 1); i <= std::min(lat_.nx - 1, i0 + 1); ++i) {
        const double ex = row[i][0] - x, ey = row[i][1] - y;
        const double d = ex * ex + ey * ey;
        if (d < best) {
          best = d;
          who = j * lat_.nx + i;
        }
      }
    }
    return who;
  }

 private:
  const std::vector<std::array<double, 2>>& spots_;
  PxLattice lat_;
  double cx_, cy_, c_ = 1, s_ = 0;
  double sure2_ = 0;
};

}  // namespace

std::vector<std::int32_t> pixel_lens_map(const optics::SensorSpec& sensor, const optics::Lattice& spot_lattice,
                                         const std::vector<std::array<double, 2>>& spots_px) {
  const LensFinder finder(sensor, spot_lattice, spots_px);
  const int w = sensor.width_px;
  std::vector<std::int32_t> map(std::size_t(w) * sensor.height_px, -1);
  tbb::parallel_for(0, sensor.height_px, [&](int y) {
    for (int x = 0; x < w; ++x) map[std::size_t(y) * w + x] = finder.lens_at(x, y);
  });
  return map;
}

ImageF make_white_correction(const Calibration& cal, const ImageF& white, double dark_level,
                             double* light_outside_fraction) {
  const optics::SensorSpec& sensor = cal.sensor;
  if (white.width != sensor.width_px || white.height != sensor.height_px) {
    throw InputError("white image is " + std::to_string(white.width) + " x " + std::to_string(white.height) +
                     " pixels, the camera file's sensor is " + std::to_string(sensor.width_px) + " x " +
                     std::to_string(sensor.height_px));
  }
  if (!(cal.microlens_image_diameter_px > 0)) {
    throw InputError(
        "white correction: the calibration carries no microlens image diameter (calibrate() "
        "sets it from the camera)");
  }
  // Finite; a dark-subtracted white may dip below 0 in its gaps (clamped to 0 below).
  for (std::size_t k = 0; k < white.size(); ++k) {
    if (!std::isfinite(white.pixels[k])) {
      throw InputError("white image: pixel (" + std::to_string(k % white.width) + ", " +
                       std::to_string(k / white.width) + ") is not a finite value");
    }
  }
  const int nx = cal.spot_lattice.count_x, ny = cal.spot_lattice.count_y;
  const double pitch_px = std::min(cal.spot_lattice.pitch_x_mm, cal.spot_lattice.pitch_y_mm) / sensor.pixel_pitch_mm;
  const double radius = 0.25 * pitch_px;
  std::vector<double> level(std::size_t(nx) * ny, 0.0);
  tbb::parallel_for(0, nx * ny, [&](int id) {
    const auto& q = cal.spots_px[id];
    double sum = 0;
    int n = 0;
    for (int y = int(std::floor(q[1] - radius)); y <= int(std::ceil(q[1] + radius)); ++y) {
      if (y < 0 || y >= white.height) continue;
      for (int x = int(std::floor(q[0] - radius)); x <= int(std::ceil(q[0] + radius)); ++x) {
        if (x < 0 || x >= white.width) continue;
        if ((x - q[0]) * (x - q[0]) + (y - q[1]) * (y - q[1]) > radius * radius) continue;
        sum += white.at(x, y) - dark_level;
        ++n;
      }
    }
    level[id] = n > 0 ? sum / n : 0.0;
  });
  const LensFinder finder(sensor, cal.spot_lattice, cal.spots_px);
  const double disk_r2 = 0.25 * cal.microlens_image_diameter_px * cal.microlens_image_diameter_px;
  ImageF out(white.width, white.height, 0.0f);
  // Per row: (signal kept, signal outside the disks), summed in row order afterwards.
  std::vector<std::array<double, 2>> signal(std::size_t(white.height), {0.0, 0.0});
  tbb::parallel_for(0, white.height, [&](int y) {
    for (int x = 0; x < white.width; ++x) {
      const int id = finder.lens_at(x, y);
      if (id < 0 || level[id] <= 0) continue;
      const double v = std::max(0.0, (white.at(x, y) - dark_level) / level[id]);
      // The point of the pixel's square nearest the spot: inside the disk means the pixel overlaps it.
      const auto& q = cal.spots_px[std::size_t(id)];
      const double ex = std::clamp(q[0], x - 0.5, x + 0.5) - q[0], ey = std::clamp(q[1], y - 0.5, y + 0.5) - q[1];
      const bool inside = ex * ex + ey * ey < disk_r2;
      signal[std::size_t(y)][inside ? 0 : 1] += v;
      if (inside) out.at(x, y) = float(v);
    }
  });
  if (light_outside_fraction) {
    double kept = 0, outside = 0;
    for (const auto& s : signal) {
      kept += s[0];
      outside += s[1];
    }
    *light_outside_fraction = kept + outside > 0 ? outside / (kept + outside) : 0.0;
  }
  return out;
}

}  // namespace plenopiv::calib
