// Microlens calibration: neighbour statistics, lattice phase, Gauss-Newton fit, per-lens centres.
#include "core/calib/calibration.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>

#include "core/base/errors.hpp"

namespace plenopiv::calib {
namespace {

// The spot lattice in pixels, relative to the sensor centre (same model as optics::Lattice).
struct PxLattice {
  bool hex = false;
  int nx = 0, ny = 0;
  double px = 0, py = 0, th = 0, ox = 0, oy = 0;

  double shift(int j) const { return hex ? ((j & 1) ? 0.25 : -0.25) : 0.0; }
  // Local lattice coordinates (in pitches) of lens (i, j).
  double la(int i, int j) const { return i - 0.5 * (nx - 1) + shift(j); }
  double lb(int j) const { return j - 0.5 * (ny - 1); }
  std::array<double, 2> position(int i, int j) const {
    const double a = la(i, j) * px, b = lb(j) * py;
    const double c = std::cos(th), s = std::sin(th);
    return {c * a + s * b + ox, -s * a + c * b + oy};
  }
  // The lattice index nearest to (x, y) (unbounded: may lie outside the array).
  std::array<int, 2> nearest(double x, double y) const {
    const double c = std::cos(th), s = std::sin(th);
    const double dx = x - ox, dy = y - oy;
    const double a = (c * dx - s * dy) / px, b = (s * dx + c * dy) / py;
    const int j = int(std::lround(b + 0.5 * (ny - 1)));
    const int i = int(std::lround(a + 0.5 * (nx - 1) - shift(j)));
    return {i, j};
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

double median(std::vector<double> v) {
  const std::size_t k = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

// Pitch and rotation from the vectors between neighbouring spots: rotation within a few degrees
// and pitch within a few percent of nominal select the in-row neighbours and the next-row ones.
void estimate_pitch_and_rotation(const std::vector<std::array<double, 2>>& p,
                                 PxLattice& lat, double nominal_px, double nominal_row_px) {
  const double cell = 1.3 * nominal_px;
  double xmin = 1e300, ymin = 1e300, xmax = -1e300, ymax = -1e300;
  for (const auto& q : p) {
    xmin = std::min(xmin, q[0]);
    xmax = std::max(xmax, q[0]);
    ymin = std::min(ymin, q[1]);
    ymax = std::max(ymax, q[1]);
  }
  const int gx = int((xmax - xmin) / cell) + 1, gy = int((ymax - ymin) / cell) + 1;
  std::vector<int> start(std::size_t(gx) * gy + 1, 0), order(p.size());
  auto cell_of = [&](const std::array<double, 2>& q) {
    return std::size_t(int((q[1] - ymin) / cell)) * gx + std::size_t(int((q[0] - xmin) / cell));
  };
  for (const auto& q : p) ++start[cell_of(q) + 1];
  for (std::size_t k = 1; k < start.size(); ++k) start[k] += start[k - 1];
  {
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (std::size_t k = 0; k < p.size(); ++k) order[fill[cell_of(p[k])]++] = int(k);
  }
  const double diag = lat.hex ? std::hypot(0.5 * nominal_px, nominal_row_px) : nominal_row_px;
  std::vector<double> row_len, row_angle;
  std::vector<std::array<double, 2>> cross;
  for (std::size_t k = 0; k < p.size(); ++k) {
    const int cx = int((p[k][0] - xmin) / cell), cy = int((p[k][1] - ymin) / cell);
    for (int ny = std::max(0, cy - 1); ny <= std::min(gy - 1, cy + 1); ++ny) {
      for (int nx = std::max(0, cx - 1); nx <= std::min(gx - 1, cx + 1); ++nx) {
        const std::size_t c = std::size_t(ny) * gx + nx;
        for (int o = start[c]; o < start[c + 1]; ++o) {
          const double vx = p[order[o]][0] - p[k][0], vy = p[order[o]][1] - p[k][1];
          const double len = std::hypot(vx, vy);
          const double angle = std::atan2(-vy, vx);  // counter-clockwise on the upright image
          if (vx > 0 && std::abs(angle) < 0.25 && std::abs(len / nominal_px - 1) < 0.15) {
            row_len.push_back(len);
            row_angle.push_back(angle);
          } else if (vy > 0 && std::abs(std::abs(angle) - 0.5 * std::numbers::pi) < 0.5 * std::numbers::pi - 0.5 &&
                     std::abs(len / diag - 1) < 0.15) {
            cross.push_back({vx, vy});
          }
        }
      }
    }
  }
  if (row_len.size() < 10 || cross.size() < 10) {
    throw InputError("calibration image: found " + count_str(long(p.size())) +
                     " spots but only " + std::to_string(row_len.size()) + " in-row and " +
                     std::to_string(cross.size()) + " next-row neighbour pairs near the nominal spot pitch of " +
                     fmt(nominal_px, 2) + " px: the spots do not form the camera file's " +
                     (lat.hex ? "hex" : "rect") + " lattice");
  }
  lat.th = median(row_angle);
  lat.px = median(row_len);
  const double c = std::cos(lat.th), s = std::sin(lat.th);
  std::vector<double> b;
  b.reserve(cross.size());
  for (const auto& v : cross) b.push_back(s * v[0] + c * v[1]);
  lat.py = median(b);
}

// Circular mean of the fractional parts of `values` (in cycles, -0.5..0.5).
double phase(const std::vector<double>& values) {
  double sc = 0, ss = 0;
  for (double v : values) {
    sc += std::cos(2 * std::numbers::pi * v);
    ss += std::sin(2 * std::numbers::pi * v);
  }
  return std::atan2(ss, sc) / (2 * std::numbers::pi);
}

// The offset modulo one lattice cell, given pitch and rotation.
void estimate_phase(const std::vector<std::array<double, 2>>& p, PxLattice& lat) {
  const double c = std::cos(lat.th), s = std::sin(lat.th);
  std::vector<double> fb(p.size()), fa(p.size());
  for (std::size_t k = 0; k < p.size(); ++k) fb[k] = (s * p[k][0] + c * p[k][1]) / lat.py + 0.5 * (lat.ny - 1);
  const double phb = phase(fb);
  for (std::size_t k = 0; k < p.size(); ++k) {
    const int j = int(std::lround(fb[k] - phb));
    fa[k] = (c * p[k][0] - s * p[k][1]) / lat.px + 0.5 * (lat.nx - 1) - lat.shift(j);
  }
  const double pha = phase(fa);
  const double a = pha * lat.px, b = phb * lat.py;
  lat.ox = c * a + s * b;
  lat.oy = -s * a + c * b;
}

// Gauss-Newton on (ox, oy, px, py, rotation) over the assigned spots; serial, so the result is
// the same at any thread count (55 k points take well under a millisecond per iteration).
void fit_lattice(const std::vector<std::array<double, 2>>& p, const std::vector<std::array<int, 2>>& ij,
                 const std::vector<std::uint8_t>& use, PxLattice& lat) {
  for (int iter = 0; iter < 6; ++iter) {
    cv::Matx<double, 5, 5> jtj = cv::Matx<double, 5, 5>::zeros();
    cv::Vec<double, 5> jtr = cv::Vec<double, 5>::all(0);
    const double c = std::cos(lat.th), s = std::sin(lat.th);
    for (std::size_t k = 0; k < p.size(); ++k) {
      if (!use[k]) continue;
      const double A = lat.la(ij[k][0], ij[k][1]), B = lat.lb(ij[k][1]);
      const auto q = lat.position(ij[k][0], ij[k][1]);
      const double rx = p[k][0] - q[0], ry = p[k][1] - q[1];
      const double jx[5] = {1, 0, c * A, s * B, -s * A * lat.px + c * B * lat.py};
      const double jy[5] = {0, 1, -s * A, c * B, -c * A * lat.px - s * B * lat.py};
      for (int a = 0; a < 5; ++a) {
        jtr[a] += jx[a] * rx + jy[a] * ry;
        for (int b = 0; b < 5; ++b) jtj(a, b) += jx[a] * jx[b] + jy[a] * jy[b];
      }
    }
    cv::Vec<double, 5> step;
    if (!cv::solve(jtj, jtr, step, cv::DECOMP_CHOLESKY)) {
      throw InputError("calibration image: the lattice fit is singular (spots on too few rows or columns)");
    }
    lat.ox += step[0];
    lat.oy += step[1];
    lat.px += step[2];
    lat.py += step[3];
    lat.th += step[4];
    if (std::abs(step[0]) + std::abs(step[1]) < 1e-9 && std::abs(step[2]) + std::abs(step[3]) < 1e-12) break;
  }
}

void assign(const std::vector<std::array<double, 2>>& p, const PxLattice& lat, std::vector<std::array<int, 2>>& ij) {
  for (std::size_t k = 0; k < p.size(); ++k) ij[k] = lat.nearest(p[k][0], p[k][1]);
}

}  // namespace

Calibration calibrate(const optics::CameraModel& camera, const ImageF& image, const CalibrationOptions& options) {
  const optics::SensorSpec& sensor = camera.sensor();
  if (image.width != sensor.width_px || image.height != sensor.height_px) {
    throw InputError("calibration image is " + std::to_string(image.width) + " x " +
                     std::to_string(image.height) + " pixels, the camera file's sensor is " +
                     std::to_string(sensor.width_px) + " x " + std::to_string(sensor.height_px));
  }
  const double s_i = camera.image_distance_mm(), f_l = camera.microlens().focal_length_mm;
  const double scale = 1.0 + f_l / s_i;  // lens lattice -> spot lattice
  const double pp = sensor.pixel_pitch_mm;
  const double nominal_px = camera.microlens().pitch_mm * scale / pp;
  const double nominal_row_px = camera.row_pitch_mm() * scale / pp;

  SpotOptions spot_options = options.spots;
  if (spot_options.max_area_px <= 0) spot_options.max_area_px = 0.5 * nominal_px * nominal_row_px;
  Calibration cal;
  cal.sensor = sensor;
  cal.image_distance_mm = s_i;
  cal.microlens_focal_length_mm = f_l;
  cal.microlens_image_diameter_px = camera.microlens_image_diameter_px();
  const std::vector<Spot> spots = find_spots(image, spot_options, &cal.image_stats);
  cal.spots_found = int(spots.size());

  const long expected = camera.lens_count();
  if (double(spots.size()) < options.min_found_fraction * double(expected) ||
      double(spots.size()) > 1.2 * double(expected)) {
    std::string why = " (detection level " + fmt(cal.image_stats.threshold, 1) + " over background " +
                      fmt(cal.image_stats.background, 1) + ", noise " + fmt(cal.image_stats.noise_sigma, 2);
    if (cal.image_stats.rejected_large > 0) {
      why += "; " + std::to_string(cal.image_stats.rejected_large) +
             " blobs larger than a spot refused: was the aperture stopped down?";
    }
    throw InputError("calibration image: found " + count_str(long(spots.size())) + " spots, expected about " +
                     count_str(expected) + " (one per microlens)" + why + ")");
  }

  // Spot positions relative to the sensor centre, in pixels.
  const double cx = 0.5 * sensor.width_px - 0.5, cy = 0.5 * sensor.height_px - 0.5;
  std::vector<std::array<double, 2>> p(spots.size());
  for (std::size_t k = 0; k < spots.size(); ++k) p[k] = {spots[k].column - cx, spots[k].row - cy};

  PxLattice lat;
  lat.hex = camera.microlens().layout == optics::LensletLayout::hex;
  lat.nx = camera.microlens().count_x;
  lat.ny = camera.microlens().count_y;
  estimate_pitch_and_rotation(p, lat, nominal_px, nominal_row_px);
  estimate_phase(p, lat);

  std::vector<std::array<int, 2>> ij(p.size());
  std::vector<std::uint8_t> use(p.size(), 1);
  for (int round = 0; round < 2; ++round) {
    assign(p, lat, ij);
    fit_lattice(p, ij, use, lat);
  }
  if (std::abs(lat.px / nominal_px - 1) > options.pitch_tolerance ||
      std::abs(lat.py / nominal_row_px - 1) > options.pitch_tolerance) {
    throw InputError("calibration image: no lattice near the camera file's explains the spots: fitted spot pitch " + fmt(lat.px) + " x " + fmt(lat.py) +
                     " px departs more than " + fmt(100 * options.pitch_tolerance, 0) +
                     "% from the camera file's " + fmt(nominal_px) + " x " + fmt(nominal_row_px) + " px");
  }

  // The fit fixes the lattice up to a whole-lens translation; pick the one that puts every spot
  // on a lens of the array and, of those, the array nearest the sensor centre (DESIGN.md).
  const double c = std::cos(lat.th), s = std::sin(lat.th);
  const std::array<double, 2> a1{c * lat.px, -s * lat.px};
  const double a2l = lat.hex ? 0.5 * lat.px : 0.0;
  const std::array<double, 2> a2{c * a2l + s * lat.py, -s * a2l + c * lat.py};
  // Spots a third of a pitch or more off their site (hot-pixel clusters, stray light) would
  // stretch the range: they do not vote.
  std::vector<std::array<double, 2>> on_lattice;
  on_lattice.reserve(p.size());
  for (const auto& q : p) {
    const auto k = lat.nearest(q[0], q[1]);
    const auto site = lat.position(k[0], k[1]);
    if (std::hypot(q[0] - site[0], q[1] - site[1]) < lat.px / 3) on_lattice.push_back(q);
  }
  auto index_range = [&](const PxLattice& t) {
    std::array<int, 4> r{1 << 30, -(1 << 30), 1 << 30, -(1 << 30)};
    for (const auto& q : on_lattice) {
      const auto k = t.nearest(q[0], q[1]);
      r = {std::min(r[0], k[0]), std::max(r[1], k[0]), std::min(r[2], k[1]), std::max(r[3], k[1])};
    }
    return r;
  };
  const auto span = index_range(lat);
  const int span_i = span[1] - span[0] + 1, span_j = span[3] - span[2] + 1;
  PxLattice best = lat;
  double best_offset = 1e300;
  for (int n = -6; n <= 6; ++n) {
    for (int m = -6; m <= 6; ++m) {
      PxLattice t = lat;
      t.ox += m * a1[0] + n * a2[0];
      t.oy += m * a1[1] + n * a2[1];
      const auto r = index_range(t);
      if (r[0] < 0 || r[2] < 0 || r[1] >= lat.nx || r[3] >= lat.ny) continue;
      const double o = std::hypot(t.ox, t.oy);
      if (o < best_offset) {
        best_offset = o;
        best = t;
      }
    }
  }
  if (best_offset == 1e300) {
    throw InputError("calibration image: the spots span " + std::to_string(span_i) + " columns by " +
                     std::to_string(span_j) + " rows of lenses, which does not fit the camera file's " +
                     std::to_string(lat.nx) + " x " + std::to_string(lat.ny) + " array near the sensor centre");
  }
  lat = best;
  assign(p, lat, ij);

  // Outliers (a hot pixel beside a spot, a stray second spot) are refused and the fit repeated.
  const std::size_t nl = std::size_t(lat.nx) * lat.ny;
  std::vector<int> owner(nl, -1);
  auto residual = [&](std::size_t k) {
    const auto q = lat.position(ij[k][0], ij[k][1]);
    return std::hypot(p[k][0] - q[0], p[k][1] - q[1]);
  };
  auto inside = [&](std::size_t k) {
    return ij[k][0] >= 0 && ij[k][1] >= 0 && ij[k][0] < lat.nx && ij[k][1] < lat.ny;
  };
  for (int round = 0; round < 2; ++round) {
    std::vector<double> r(p.size());
    for (std::size_t k = 0; k < p.size(); ++k) r[k] = residual(k);
    const double limit = std::max(options.outlier_px, 3.0 * median(r));
    std::fill(owner.begin(), owner.end(), -1);
    for (std::size_t k = 0; k < p.size(); ++k) {
      use[k] = r[k] <= limit && inside(k);
      const std::size_t id = std::size_t(ij[k][1]) * lat.nx + ij[k][0];
      if (!use[k]) continue;
      if (owner[id] >= 0) {  // two spots on one lens: keep the one nearer the lattice
        if (r[owner[id]] <= r[k]) {
          use[k] = 0;
          continue;
        }
        use[owner[id]] = 0;
      }
      owner[id] = int(k);
    }
    fit_lattice(p, ij, use, lat);
  }

  cal.spot_lattice.layout = camera.microlens().layout;
  cal.spot_lattice.count_x = lat.nx;
  cal.spot_lattice.count_y = lat.ny;
  cal.spot_lattice.pitch_x_mm = lat.px * pp;
  cal.spot_lattice.pitch_y_mm = lat.py * pp;
  cal.spot_lattice.rotation_rad = lat.th;
  cal.spot_lattice.offset_x_mm = lat.ox * pp;
  cal.spot_lattice.offset_y_mm = lat.oy * pp;

  cal.spots_px.resize(nl);
  cal.status.assign(nl, LensStatus::missing);
  cal.residuals_px.assign(nl, {0.0, 0.0});
  for (int j = 0; j < lat.ny; ++j) {
    for (int i = 0; i < lat.nx; ++i) {
      const auto q = lat.position(i, j);
      cal.spots_px[std::size_t(j) * lat.nx + i] = {q[0] + cx, q[1] + cy};
    }
  }
  double sum2 = 0;
  for (std::size_t k = 0; k < p.size(); ++k) {
    if (!inside(k)) continue;
    const std::size_t id = std::size_t(ij[k][1]) * lat.nx + ij[k][0];
    const auto q = lat.position(ij[k][0], ij[k][1]);
    const std::array<double, 2> r{p[k][0] - q[0], p[k][1] - q[1]};
    if (use[k]) {
      cal.status[id] = LensStatus::measured;
      cal.residuals_px[id] = r;
      cal.spots_px[id] = {spots[k].column, spots[k].row};
      sum2 += r[0] * r[0] + r[1] * r[1];
      cal.max_residual_px = std::max(cal.max_residual_px, std::hypot(r[0], r[1]));
      ++cal.lenses_measured;
    } else if (cal.status[id] == LensStatus::missing) {
      cal.status[id] = LensStatus::rejected;
      cal.residuals_px[id] = r;
    }
  }
  cal.rms_residual_px = cal.lenses_measured > 0 ? std::sqrt(sum2 / cal.lenses_measured) : 0.0;
  return cal;
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
    const double inscribed = 0.5 * (lat_.hex ? std::min(lat_.px, std::hypot(0.5 * lat_.px, lat_.py))
                                             : std::min(lat_.px, lat_.py));
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
    throw InputError("white correction: the calibration carries no microlens image diameter (calibrate() "
                     "sets it from the camera)");
  }
  for (std::size_t k = 0; k < white.size(); ++k) {
    if (!std::isfinite(white.pixels[k]) || white.pixels[k] < 0) {
      throw InputError("white image: pixel (" + std::to_string(k % white.width) + ", " +
                       std::to_string(k / white.width) + ") is not a finite, non-negative value");
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
