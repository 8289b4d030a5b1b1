// Microlens lattices in sensor pixels: neighbour statistics, circular-mean phase, Gauss-Newton,
// polynomial distortion chosen by BIC.
#include "core/calib/lattice_fit.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <sstream>

#include "core/base/errors.hpp"

namespace plenopiv::calib {
namespace {

// v with two decimals.
std::string fixed2(double v) {
  std::ostringstream s;
  s.precision(2);
  s << std::fixed << v;
  return s.str();
}

double median_or_zero(std::vector<double> v) {
  if (v.empty()) return 0;
  const std::size_t k = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

// Points binned in square cells of `cell` pixels, for neighbour searches.
class PointGrid {
 public:
  PointGrid(const std::vector<std::array<double, 2>>& p, double cell) : p_(p), cell_(cell) {
    for (const auto& q : p) {
      lo_[0] = std::min(lo_[0], q[0]);
      lo_[1] = std::min(lo_[1], q[1]);
      hi_[0] = std::max(hi_[0], q[0]);
      hi_[1] = std::max(hi_[1], q[1]);
    }
    gx_ = int((hi_[0] - lo_[0]) / cell_) + 1;
    gy_ = int((hi_[1] - lo_[1]) / cell_) + 1;
    start_.assign(std::size_t(gx_) * gy_ + 1, 0);
    order_.resize(p.size());
    for (const auto& q : p) ++start_[index(q) + 1];
    for (std::size_t k = 1; k < start_.size(); ++k) start_[k] += start_[k - 1];
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (std::size_t k = 0; k < p.size(); ++k) order_[std::size_t(fill[index(p[k])]++)] = int(k);
  }
  // Calls f(other index) for every point in the 3 x 3 cells around point k.
  template <typename F>
  void around(std::size_t k, F&& f) const {
    const int cx = int((p_[k][0] - lo_[0]) / cell_), cy = int((p_[k][1] - lo_[1]) / cell_);
    for (int y = std::max(0, cy - 1); y <= std::min(gy_ - 1, cy + 1); ++y) {
      for (int x = std::max(0, cx - 1); x <= std::min(gx_ - 1, cx + 1); ++x) {
        const std::size_t c = std::size_t(y) * gx_ + x;
        for (int o = start_[c]; o < start_[c + 1]; ++o) {
          if (std::size_t(order_[std::size_t(o)]) != k) f(std::size_t(order_[std::size_t(o)]));
        }
      }
    }
  }

 private:
  std::size_t index(const std::array<double, 2>& q) const {
    return std::size_t(int((q[1] - lo_[1]) / cell_)) * gx_ + std::size_t(int((q[0] - lo_[0]) / cell_));
  }
  const std::vector<std::array<double, 2>>& p_;
  double cell_;
  double lo_[2] = {1e300, 1e300}, hi_[2] = {-1e300, -1e300};
  int gx_ = 1, gy_ = 1;
  std::vector<int> start_, order_;
};

// Circular mean of the fractional parts of `values` (in cycles, -0.5..0.5).
double phase(const std::vector<double>& values) {
  double sc = 0, ss = 0;
  for (double v : values) {
    sc += std::cos(2 * std::numbers::pi * v);
    ss += std::sin(2 * std::numbers::pi * v);
  }
  return std::atan2(ss, sc) / (2 * std::numbers::pi);
}

// Polynomial terms u^m v^n with m + n <= degree, in a fixed order.
std::vector<std::array<int, 2>> terms(int degree) {
  std::vector<std::array<int, 2>> t;
  for (int d = 0; d <= degree; ++d) {
    for (int n = 0; n <= d; ++n) t.push_back({d - n, n});
  }
  return t;
}

}  // namespace

std::array<double, 2> RawLattice::at(double a, double b) const {
  const double c = std::cos(rotation), s = std::sin(rotation);
  return {ox + c * a * px + s * b * py, oy - s * a * px + c * b * py};
}

std::array<double, 2> RawLattice::coords(double x, double y) const {
  const double c = std::cos(rotation), s = std::sin(rotation);
  const double dx = x - ox, dy = y - oy;
  return {(c * dx - s * dy) / px, (s * dx + c * dy) / py};
}

std::array<int, 2> RawLattice::nearest(double x, double y) const {
  return nearest(x, y, std::cos(rotation), std::sin(rotation));
}

std::array<int, 2> RawLattice::nearest(double x, double y, double c, double s) const {
  const double dx = x - ox, dy = y - oy;
  const std::array<double, 2> ab{(c * dx - s * dy) / px, (s * dx + c * dy) / py};
  if (!hex) return {int(std::lround(ab[0])), int(std::lround(ab[1]))};
  // Hex: the nearest lens is on the nearest row or the one beside it.
  const int j0 = int(std::floor(ab[1]));
  std::array<int, 2> best{0, 0};
  double best_d = 1e300;
  for (int j = j0; j <= j0 + 1; ++j) {
    const int i = int(std::lround(ab[0] - shift(j)));
    const double da = (ab[0] - i - shift(j)) * px, db = (ab[1] - j) * py;
    const double d = da * da + db * db;
    if (d < best_d) {
      best_d = d;
      best = {i, j};
    }
  }
  return best;
}

double median_neighbour_distance(const std::vector<std::array<double, 2>>& p) {
  if (p.size() < 2) return 0;
  // A cell a few times the typical spacing: the nearest neighbour is in the 3 x 3 cells around.
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (const auto& q : p) {
    xmin = std::min(xmin, q[0]);
    xmax = std::max(xmax, q[0]);
    ymin = std::min(ymin, q[1]);
    ymax = std::max(ymax, q[1]);
  }
  const double spacing = std::sqrt(std::max(1.0, (xmax - xmin) * (ymax - ymin)) / double(p.size()));
  const PointGrid grid(p, 2.5 * spacing);
  std::vector<double> d;
  d.reserve(p.size());
  for (std::size_t k = 0; k < p.size(); ++k) {
    double best = 1e300;
    grid.around(k, [&](std::size_t o) { best = std::min(best, std::hypot(p[o][0] - p[k][0], p[o][1] - p[k][1])); });
    if (best < 1e300) d.push_back(best);
  }
  return median_or_zero(d);
}

RawLattice estimate_lattice(const std::vector<std::array<double, 2>>& p, bool hex, double pitch_px,
                            const std::string& what) {
  RawLattice lat;
  lat.hex = hex;
  const double row_px = hex ? pitch_px * std::sqrt(3.0) / 2 : pitch_px;
  const double diag = hex ? std::hypot(0.5 * pitch_px, row_px) : row_px;  // next-row neighbour
  const PointGrid grid(p, 1.3 * pitch_px);
  std::vector<double> row_len, row_angle;
  std::vector<std::array<double, 2>> cross;
  for (std::size_t k = 0; k < p.size(); ++k) {
    grid.around(k, [&](std::size_t o) {
      const double vx = p[o][0] - p[k][0], vy = p[o][1] - p[k][1];
      const double len = std::hypot(vx, vy);
      const double angle = std::atan2(-vy, vx);  // counter-clockwise on the upright image
      if (vx > 0 && std::abs(angle) < 0.25 && std::abs(len / pitch_px - 1) < 0.15) {
        row_len.push_back(len);
        row_angle.push_back(angle);
      } else if (vy > 0 && std::abs(std::abs(angle) - 0.5 * std::numbers::pi) < 0.5 * std::numbers::pi - 0.5 &&
                 std::abs(len / diag - 1) < 0.15) {
        cross.push_back({vx, vy});
      }
    });
  }
  if (row_len.size() < 10 || cross.size() < 10) {
    throw InputError("found " + std::to_string(p.size()) + " " + what + " but only " + std::to_string(row_len.size()) +
                     " in-row and " + std::to_string(cross.size()) + " next-row neighbour pairs near a pitch of " +
                     fixed2(pitch_px) + " px: they do not form a " + (hex ? "hex" : "rect") +
                     " lattice (check microlens.layout, and that the array's rows run "
                     "within 14 deg of the sensor's)");
  }
  lat.rotation = median_or_zero(row_angle);
  lat.px = median_or_zero(row_len);
  const double c = std::cos(lat.rotation), s = std::sin(lat.rotation);
  std::vector<double> b;
  b.reserve(cross.size());
  for (const auto& v : cross) b.push_back(s * v[0] + c * v[1]);
  lat.py = median_or_zero(b);

  // Phase: rows from the circular mean of b, then positions along each row.
  std::vector<double> fb(p.size()), fa(p.size());
  for (std::size_t k = 0; k < p.size(); ++k) fb[k] = (s * p[k][0] + c * p[k][1]) / lat.py;
  const double phb = phase(fb);
  for (std::size_t k = 0; k < p.size(); ++k) {
    const int j = int(std::lround(fb[k] - phb));
    fa[k] = (c * p[k][0] - s * p[k][1]) / lat.px - lat.shift(j);
  }
  const double pha = phase(fa);
  lat.ox = c * pha * lat.px + s * phb * lat.py;
  lat.oy = -s * pha * lat.px + c * phb * lat.py;
  // Lens (0, 0): the one nearest the points' centre, on an even row so that h(j) keeps its parity.
  double mx = 0, my = 0;
  for (const auto& q : p) {
    mx += q[0];
    my += q[1];
  }
  auto n = lat.nearest(mx / double(p.size()), my / double(p.size()));
  if (hex && (n[1] & 1)) --n[1];
  const auto o = lat.site(n[0], n[1]);
  lat.ox = o[0];
  lat.oy = o[1];
  return lat;
}

void refine_lattice(const std::vector<std::array<double, 2>>& p, const std::vector<std::array<int, 2>>& ij,
                    const std::vector<double>& weight, RawLattice& lat) {
  for (int iter = 0; iter < 8; ++iter) {
    cv::Matx<double, 5, 5> jtj = cv::Matx<double, 5, 5>::zeros();
    cv::Vec<double, 5> jtr = cv::Vec<double, 5>::all(0);
    const double c = std::cos(lat.rotation), s = std::sin(lat.rotation);
    for (std::size_t k = 0; k < p.size(); ++k) {
      const double w = weight[k];
      if (!(w > 0)) continue;
      const double A = ij[k][0] + lat.shift(ij[k][1]), B = ij[k][1];
      const auto q = lat.at(A, B);
      const double rx = p[k][0] - q[0], ry = p[k][1] - q[1];
      const double jx[5] = {1, 0, c * A, s * B, -s * A * lat.px + c * B * lat.py};
      const double jy[5] = {0, 1, -s * A, c * B, -c * A * lat.px - s * B * lat.py};
      for (int a = 0; a < 5; ++a) {
        jtr[a] += w * (jx[a] * rx + jy[a] * ry);
        for (int b = 0; b < 5; ++b) jtj(a, b) += w * (jx[a] * jx[b] + jy[a] * jy[b]);
      }
    }
    cv::Vec<double, 5> step;
    if (!cv::solve(jtj, jtr, step, cv::DECOMP_CHOLESKY)) {
      throw InputError("the lattice fit is singular: the micro-images found span too few rows or columns");
    }
    lat.ox += step[0];
    lat.oy += step[1];
    lat.px += step[2];
    lat.py += step[3];
    lat.rotation += step[4];
    if (std::abs(step[0]) + std::abs(step[1]) < 1e-10 && std::abs(step[2]) + std::abs(step[3]) < 1e-12) break;
  }
}

std::array<double, 2> LatticeModel::position(int i, int j) const {
  auto q = lattice.site(i, j);
  if (degree == 0) return q;
  // Within the fitted lenses' extent (-1..1); beyond it the distortion is held, not extrapolated.
  const double u = std::clamp((i + lattice.shift(j) - centre[0]) / scale[0], -1.0, 1.0);
  const double v = std::clamp((j - centre[1]) / scale[1], -1.0, 1.0);
  const auto t = terms(degree);
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double f = std::pow(u, t[k][0]) * std::pow(v, t[k][1]);
    q[0] += cx[k] * f;
    q[1] += cy[k] * f;
  }
  return q;
}

LatticeModel fit_model(const std::vector<std::array<double, 2>>& p, const std::vector<std::array<int, 2>>& ij,
                       const std::vector<double>& weight, const RawLattice& lattice, int max_degree,
                       std::vector<double>* degree_rss) {
  LatticeModel best;
  best.lattice = lattice;
  refine_lattice(p, ij, weight, best.lattice);
  double wsum = 0, amin[2] = {1e300, 1e300}, amax[2] = {-1e300, -1e300};
  std::size_t n = 0;
  for (std::size_t k = 0; k < p.size(); ++k) {
    if (!(weight[k] > 0)) continue;
    wsum += weight[k];
    ++n;
    const double a = ij[k][0] + lattice.shift(ij[k][1]), b = ij[k][1];
    amin[0] = std::min(amin[0], a);
    amax[0] = std::max(amax[0], a);
    amin[1] = std::min(amin[1], b);
    amax[1] = std::max(amax[1], b);
  }
  auto rss_of = [&](const LatticeModel& m) {
    double s = 0;
    for (std::size_t k = 0; k < p.size(); ++k) {
      if (!(weight[k] > 0)) continue;
      const auto q = m.position(ij[k][0], ij[k][1]);
      s += weight[k] * ((p[k][0] - q[0]) * (p[k][0] - q[0]) + (p[k][1] - q[1]) * (p[k][1] - q[1]));
    }
    return s / wsum;  // weighted mean square over both axes, per point
  };
  // BIC on 2n residuals: 2n ln(RSS) + (parameters) ln(2n). The lattice has 5 parameters; a
  // polynomial of degree d >= 1 in x and y holds every affine map, the lattice among them, so the
  // model has its 2 (d + 1)(d + 2) / 2 coefficients in all.
  const double n2 = 2.0 * double(n);
  double best_rss = rss_of(best);
  if (degree_rss) degree_rss->assign(1, best_rss);
  double best_bic = n2 * std::log(std::max(best_rss, 1e-30)) + 5 * std::log(n2);
  for (int d = 1; d <= max_degree; ++d) {
    const auto t = terms(d);
    const int k = int(t.size());
    if (double(n) < 4.0 * k) break;  // too few lenses to fit the terms reliably
    LatticeModel m;
    m.lattice = best.lattice;
    m.degree = d;
    m.centre = {0.5 * (amin[0] + amax[0]), 0.5 * (amin[1] + amax[1])};
    m.scale = {std::max(1.0, 0.5 * (amax[0] - amin[0])), std::max(1.0, 0.5 * (amax[1] - amin[1]))};
    // Linear least squares of the residuals from the lattice on the terms.
    cv::Mat a = cv::Mat::zeros(k, k, CV_64F), bx = cv::Mat::zeros(k, 1, CV_64F), by = cv::Mat::zeros(k, 1, CV_64F);
    std::vector<double> f(static_cast<std::size_t>(k));
    for (std::size_t q = 0; q < p.size(); ++q) {
      const double w = weight[q];
      if (!(w > 0)) continue;
      const double u = (ij[q][0] + lattice.shift(ij[q][1]) - m.centre[0]) / m.scale[0];
      const double v = (ij[q][1] - m.centre[1]) / m.scale[1];
      for (int r = 0; r < k; ++r)
        f[std::size_t(r)] = std::pow(u, t[std::size_t(r)][0]) * std::pow(v, t[std::size_t(r)][1]);
      const auto s = m.lattice.site(ij[q][0], ij[q][1]);
      const double rx = p[q][0] - s[0], ry = p[q][1] - s[1];
      for (int r = 0; r < k; ++r) {
        bx.at<double>(r) += w * f[std::size_t(r)] * rx;
        by.at<double>(r) += w * f[std::size_t(r)] * ry;
        for (int c = 0; c < k; ++c) a.at<double>(r, c) += w * f[std::size_t(r)] * f[std::size_t(c)];
      }
    }
    cv::Mat cx, cy;
    if (!cv::solve(a, bx, cx, cv::DECOMP_SVD) || !cv::solve(a, by, cy, cv::DECOMP_SVD)) break;
    m.cx.assign(cx.begin<double>(), cx.end<double>());
    m.cy.assign(cy.begin<double>(), cy.end<double>());
    const double rss = rss_of(m);
    if (degree_rss) degree_rss->push_back(rss);
    const double bic = n2 * std::log(std::max(rss, 1e-30)) + 2.0 * k * std::log(n2);
    if (bic < best_bic) {
      best_bic = bic;
      best = m;
      best_rss = rss;
    }
  }
  return best;
}

}  // namespace plenopiv::calib
