// Micro-images: smoothed maxima, hot pixels, the point-symmetric template and per-lens fits.
#include "core/calib/micro_images.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace plenopiv::calib {
namespace {

double percentile(std::vector<float> v, double q) {
  if (v.empty()) return 0;
  const std::size_t k = std::min(v.size() - 1, std::size_t(q * double(v.size() - 1)));
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

// A strided sample of ~1 M values (an odd stride, so it does not march down one column).
std::vector<float> sample_of(const cv::Mat& m) {
  const std::size_t n = std::size_t(m.rows) * std::size_t(m.cols);
  const std::size_t step = std::max<std::size_t>(1, n / 1000000) | 1;
  std::vector<float> s;
  s.reserve(n / step + 1);
  for (std::size_t k = 0; k < n; k += step)
    s.push_back(m.at<float>(int(k / std::size_t(m.cols)), int(k % std::size_t(m.cols))));
  return s;
}

// Tukey's biweight at c = 4.685 standard deviations (95 % efficiency on Gaussian noise).
double tukey(double z) {
  const double u = z / 4.685;
  return std::abs(u) < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
}

}  // namespace

Candidates find_candidates(const ImageF& image, double pitch_px, double smoothing, double fraction) {
  Candidates out;
  const cv::Mat src(image.height, image.width, CV_32F, const_cast<float*>(image.pixels.data()));
  cv::Mat smooth;
  cv::GaussianBlur(src, smooth, cv::Size(0, 0), std::max(0.7, smoothing * pitch_px), 0, cv::BORDER_REPLICATE);
  const std::vector<float> s = sample_of(smooth);
  out.background = percentile(s, 0.02);
  out.bright = percentile(s, 0.995);
  out.threshold = out.background + fraction * (out.bright - out.background);
  if (!(out.bright > out.background + 1e-6 * std::max(1.0, std::abs(out.bright)))) return out;  // flat
  const int r = std::max(1, int(std::lround(0.33 * pitch_px)));
  cv::Mat peak;
  cv::dilate(smooth, peak, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
  for (int y = 0; y < image.height; ++y) {
    const float* a = smooth.ptr<float>(y);
    const float* b = peak.ptr<float>(y);
    for (int x = 0; x < image.width; ++x) {
      if (a[x] >= b[x] && a[x] > out.threshold) {
        // Sub-pixel: the vertex of a parabola through the maximum and its neighbours.
        double dx = 0, dy = 0;
        if (x > 0 && x + 1 < image.width) {
          const double l = a[x - 1], c = a[x], rr = a[x + 1];
          const double den = l - 2 * c + rr;
          if (den < 0) dx = std::clamp(0.5 * (l - rr) / den, -0.5, 0.5);
        }
        if (y > 0 && y + 1 < image.height) {
          const double u = smooth.at<float>(y - 1, x), c = a[x], d = smooth.at<float>(y + 1, x);
          const double den = u - 2 * c + d;
          if (den < 0) dy = std::clamp(0.5 * (u - d) / den, -0.5, 0.5);
        }
        out.points.push_back({x + dx, y + dy});
      }
    }
  }
  return out;
}

double pixel_noise(const ImageF& image) {
  const cv::Mat src(image.height, image.width, CV_32F, const_cast<float*>(image.pixels.data()));
  cv::Mat med;
  cv::medianBlur(src, med, 3);
  cv::Mat diff = cv::abs(src - med);
  // The median of |x - median3x3| of Gaussian noise is about 0.52 of one pixel's sigma... over a
  // plateau; edges only add. 1.4826 MAD / 0.52 ~ 2.85 MAD is the sigma there.
  return 2.85 * percentile(sample_of(diff), 0.5);
}

int remove_hot_pixels(ImageF& image, double background, double noise, double ratio,
                      const std::vector<std::array<double, 2>>& keep, double keep_radius) {
  const int w = image.width, h = image.height;
  cv::Mat kept(h, w, CV_8U, cv::Scalar(0));
  for (const auto& q : keep) {
    cv::circle(kept, cv::Point(int(std::lround(q[0])), int(std::lround(q[1]))), int(std::ceil(keep_radius)),
               cv::Scalar(255), cv::FILLED);
  }
  std::vector<std::vector<std::pair<std::size_t, float>>> rows(std::size_t(std::max(h, 0)));
  tbb::parallel_for(1, h - 1, [&](int y) {
    const std::uint8_t* k = kept.ptr<std::uint8_t>(y);
    for (int x = 1; x + 1 < w; ++x) {
      if (k[x]) continue;
      const float v = image.at(x, y);
      float nb[8];
      int n = 0;
      float top = -1e30f;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0) continue;
          nb[n] = image.at(x + dx, y + dy);
          top = std::max(top, nb[n]);
          ++n;
        }
      }
      if (v - top > 10 * noise && v - background > ratio * std::max(double(top) - background, noise)) {
        std::nth_element(nb, nb + 4, nb + 8);
        rows[std::size_t(y)].push_back({std::size_t(y) * w + x, nb[4]});
      }
    }
  });
  int count = 0;
  for (const auto& r : rows) {
    for (const auto& [k, v] : r) {
      image.pixels[k] = v;
      ++count;
    }
  }
  return count;
}

MicroImageTemplate::MicroImageTemplate(const ImageF& image, const RawLattice& lattice,
                                       const std::vector<std::array<int, 2>>& sites, const std::vector<LensFit>& lenses,
                                       const std::vector<std::uint8_t>& use)
    : lattice_(lattice) {
  // The cell's corners: rect (px/2, py/2); hex the hexagon's vertices (0, y0) and (px/2, y1).
  if (lattice.hex) {
    const double y0 = (0.25 * lattice.px * lattice.px + lattice.py * lattice.py) / (2 * lattice.py);
    const double y1 = (lattice.py * lattice.py - 0.25 * lattice.px * lattice.px) / (2 * lattice.py);
    corner_ = std::max(y0, std::hypot(0.5 * lattice.px, y1));
  } else {
    corner_ = std::hypot(0.5 * lattice.px, 0.5 * lattice.py);
  }
  radius_ = corner_ + 1.5;
  oversample_ = std::clamp(int(std::ceil(64.0 / radius_)), 2, 8);
  n_ = 2 * int(std::ceil(radius_ * oversample_)) + 1;
  const double c = 0.5 * (n_ - 1), S = oversample_;
  // Per bin, a local linear fit (value and slope) of the samples within one bin of its centre,
  // weighted by a tent: unlike a plain average it is not pulled by samples crowding one side of
  // the bin, as the offsets of a regular (rotated) lattice of lenses do.
  struct Moments {
    double w = 0, x = 0, y = 0, xx = 0, xy = 0, yy = 0, v = 0, vx = 0, vy = 0;
  };
  std::vector<Moments> mom(std::size_t(n_) * n_);
  const double pitch = lattice.px;
  // Serial: the sums come out the same at any thread count.
  for (std::size_t k = 0; k < sites.size(); ++k) {
    if (!use[k]) continue;
    const LensFit& l = lenses[k];
    if (!(l.amplitude > 0)) continue;
    // Every pixel within the grid's reach, not only the lens's cell: a lens that moves by a
    // fraction of a pixel from its lattice site reads the template beyond its cell's edge (where
    // the mean includes its neighbours' light, as its own pixels do).
    const int x0 = std::max(0, int(std::floor(l.centre[0] - radius_))),
              x1 = std::min(image.width - 1, int(std::ceil(l.centre[0] + radius_)));
    const int y0 = std::max(0, int(std::floor(l.centre[1] - radius_))),
              y1 = std::min(image.height - 1, int(std::ceil(l.centre[1] + radius_)));
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const double dx = x - l.centre[0], dy = y - l.centre[1];
        const double u = dx * S + c, v = dy * S + c;
        if (u < 0 || v < 0 || u >= n_ - 1 || v >= n_ - 1) continue;
        const double scale = l.amplitude + (l.tilt[0] * dx + l.tilt[1] * dy) / pitch;
        if (scale < 0.2 * l.amplitude) continue;
        const double value = (image.at(x, y) - l.background) / scale;
        const int u0 = int(u), v0 = int(v);
        for (int bv = v0; bv <= v0 + 1; ++bv) {
          for (int bu = u0; bu <= u0 + 1; ++bu) {
            const double ex = u - bu, ey = v - bv;  // sample offset from the bin centre, in bins
            const double wq = (1 - std::abs(ex)) * (1 - std::abs(ey));
            Moments& m = mom[std::size_t(bv) * n_ + bu];
            m.w += wq;
            m.x += wq * ex;
            m.y += wq * ey;
            m.xx += wq * ex * ex;
            m.xy += wq * ex * ey;
            m.yy += wq * ey * ey;
            m.v += wq * value;
            m.vx += wq * value * ex;
            m.vy += wq * value * ey;
          }
        }
      }
  }
  // Mean per bin, then point symmetry; empty bins take their mirror's value, or none.
  const std::size_t n2 = std::size_t(n_) * n_;
  std::vector<double> mean(n2, std::nan(""));
  for (std::size_t k = 0; k < n2; ++k) {
    const Moments& m = mom[k];
    if (!(m.w > 1e-3)) continue;
    const cv::Matx33d a(m.w, m.x, m.y, m.x, m.xx, m.xy, m.y, m.xy, m.yy);
    const cv::Vec3d b(m.v, m.vx, m.vy);
    cv::Vec3d sol;
    // Too few or too lined-up samples for a slope: their mean.
    const bool sloped = cv::determinant(a) > 1e-6 * m.w * m.w * m.w && cv::solve(a, b, sol, cv::DECOMP_CHOLESKY);
    mean[k] = sloped ? sol[0] : m.v / m.w;
  }
  value_.assign(n2, 0.0f);
  std::vector<double> symmetric(n2, std::nan(""));
  std::vector<float> valid_values;
  for (std::size_t k = 0; k < n2; ++k) {
    const double a = mean[k], b = mean[n2 - 1 - k];
    double v = std::nan("");
    if (std::isfinite(a) && std::isfinite(b)) {
      v = 0.5 * (a + b);
    } else if (std::isfinite(a)) {
      v = a;
    } else if (std::isfinite(b)) {
      v = b;
    }
    symmetric[k] = v;
    if (std::isfinite(v)) valid_values.push_back(float(v));
  }
  mean.swap(symmetric);
  const double floor = percentile(valid_values, 0.02);
  double peak = floor;
  for (float v : valid_values) peak = std::max(peak, double(v));
  const double span = peak > floor ? peak - floor : 1.0;
  for (std::size_t k = 0; k < n2; ++k) value_[k] = std::isfinite(mean[k]) ? float((mean[k] - floor) / span) : 0.0f;
  // Gradients per pixel of offset: central differences on the fine grid.
  grad_x_.assign(n2, 0.0f);
  grad_y_.assign(n2, 0.0f);
  for (int v = 0; v < n_; ++v) {
    for (int u = 0; u < n_; ++u) {
      const int ul = std::max(0, u - 1), ur = std::min(n_ - 1, u + 1);
      const int vu = std::max(0, v - 1), vd = std::min(n_ - 1, v + 1);
      const std::size_t k = std::size_t(v) * n_ + u;
      grad_x_[k] = float((value_[std::size_t(v) * n_ + ur] - value_[std::size_t(v) * n_ + ul]) * S / (ur - ul));
      grad_y_[k] = float((value_[std::size_t(vd) * n_ + u] - value_[std::size_t(vu) * n_ + u]) * S / (vd - vu));
    }
  }
  packed_.resize(n2);
  for (std::size_t k = 0; k < n2; ++k) packed_[k] = {value_[k], grad_x_[k], grad_y_[k]};
}

void MicroImageTemplate::value_and_gradient(double dx, double dy, double& v, double& gx, double& gy) const {
  const double c = 0.5 * (n_ - 1);
  const double u = dx * oversample_ + c, w = dy * oversample_ + c;
  if (!(u >= 0 && w >= 0 && u < n_ - 1 && w < n_ - 1)) {
    v = gx = gy = 0;
    return;
  }
  const int u0 = int(u), w0 = int(w);
  const float tu = float(u - u0), tw = float(w - w0);
  const std::array<float, 3>* a = &packed_[std::size_t(w0) * n_ + u0];
  const std::array<float, 3>* b = a + n_;
  const float w00 = (1 - tu) * (1 - tw), w01 = tu * (1 - tw), w10 = (1 - tu) * tw, w11 = tu * tw;
  v = w00 * a[0][0] + w01 * a[1][0] + w10 * b[0][0] + w11 * b[1][0];
  gx = w00 * a[0][1] + w01 * a[1][1] + w10 * b[0][1] + w11 * b[1][1];
  gy = w00 * a[0][2] + w01 * a[1][2] + w10 * b[0][2] + w11 * b[1][2];
}

double MicroImageTemplate::sample(const std::vector<float>& grid, double dx, double dy) const {
  const double c = 0.5 * (n_ - 1);
  const double u = dx * oversample_ + c, v = dy * oversample_ + c;
  if (!(u >= 0 && v >= 0 && u < n_ - 1 && v < n_ - 1)) return 0.0;
  const int u0 = int(u), v0 = int(v);
  const double tu = u - u0, tv = v - v0;
  const float* a = &grid[std::size_t(v0) * n_ + u0];
  const float* b = a + n_;
  return (1 - tv) * ((1 - tu) * a[0] + tu * a[1]) + tv * ((1 - tu) * b[0] + tu * b[1]);
}

double MicroImageTemplate::value(double dx, double dy) const { return sample(value_, dx, dy); }

double MicroImageTemplate::radius_at(double level) const {
  // Directions to the cell's corners in the lattice's own frame, turned by its rotation.
  std::vector<std::array<double, 2>> corners;
  const double px = lattice_.px, py = lattice_.py;
  if (lattice_.hex) {
    const double y0 = (0.25 * px * px + py * py) / (2 * py), y1 = (py * py - 0.25 * px * px) / (2 * py);
    corners = {{0, y0}, {0, -y0}, {0.5 * px, y1}, {-0.5 * px, y1}, {0.5 * px, -y1}, {-0.5 * px, -y1}};
  } else {
    corners = {{0.5 * px, 0.5 * py}, {-0.5 * px, 0.5 * py}, {0.5 * px, -0.5 * py}, {-0.5 * px, -0.5 * py}};
  }
  const double c = std::cos(lattice_.rotation), s = std::sin(lattice_.rotation);
  // The centre's level: the mean over a disk of a tenth of the pitch.
  double centre = 0;
  int n = 0;
  const double r0 = std::max(0.5, 0.1 * px);
  for (double y = -r0; y <= r0; y += 0.25) {
    for (double x = -r0; x <= r0; x += 0.25) {
      if (x * x + y * y > r0 * r0) continue;
      centre += value(x, y);
      ++n;
    }
  }
  centre /= std::max(n, 1);
  double total = 0;
  for (const auto& k : corners) {
    const double ex = c * k[0] + s * k[1], ey = -s * k[0] + c * k[1];
    const double len = std::hypot(ex, ey);
    double found = len;
    double prev = centre;
    for (double r = 0.05; r <= len; r += 0.05) {
      const double v = value(ex * r / len, ey * r / len);
      if (v < level * centre) {
        found = r - 0.05 * (level * centre - v) / std::max(prev - v, 1e-12);
        break;
      }
      prev = v;
    }
    total += found;
  }
  return total / double(corners.size());
}

std::vector<LensFit> fit_lenses(const ImageF& image, const RawLattice& lattice,
                                const std::vector<std::array<int, 2>>& sites, const std::vector<LensFit>& start,
                                const MicroImageTemplate& shape, bool fit_tilt, const NoiseModel& noise) {
  std::vector<LensFit> out(sites.size());
  const double pitch = lattice.px;
  const double cell_area = lattice.px * lattice.py;
  const int P = fit_tilt ? 6 : 4;  // dx, dy, a, b (, gx, gy)
  tbb::parallel_for(std::size_t(0), sites.size(), [&](std::size_t k) {
    LensFit f = start[k];
    f.converged = false;
    // Per pixel: its offset from the starting centre, its value, and per iteration the template
    // there (value, gradient), its variance and weight.
    struct Px {
      float ex, ey, v;
      float t, tx, ty;
      double r, var, z;
    };
    std::vector<Px> px;
    px.reserve(std::size_t(cell_area * 1.2) + 16);
    const std::array<double, 2> c0 = start[k].centre;
    for_each_cell_pixel(lattice, sites[k][0], sites[k][1], image.width, image.height, [&](int x, int y) {
      px.push_back({float(x - c0[0]), float(y - c0[1]), image.at(x, y), 0, 0, 0, 0, 1, 0});
    });
    f.visible = std::min(1.0, double(px.size()) / cell_area);
    if (px.size() < std::size_t(3 * P)) {
      out[k] = f;
      return;
    }
    double p_[6] = {0, 0, start[k].amplitude, start[k].background, start[k].tilt[0], start[k].tilt[1]};
    const double inv_pitch = 1.0 / pitch;
    double zscale = 1;
    // Model, residual, variance and normalised residual of every pixel at the current parameters.
    auto evaluate = [&] {
      for (Px& q : px) {
        double t, tx, ty;
        shape.value_and_gradient(q.ex - p_[0], q.ey - p_[1], t, tx, ty);
        q.t = float(t);
        q.tx = float(tx);
        q.ty = float(ty);
        const double m = p_[3] + (p_[2] + (p_[4] * q.ex + p_[5] * q.ey) * inv_pitch) * t;
        q.r = q.v - m;
        q.var = noise.robust ? noise.floor + noise.gain * std::max(0.0, m - p_[3]) : 1.0;
        q.z = q.r / std::sqrt(std::max(q.var, 1e-12));
      }
    };
    auto robust_scale = [&] {
      std::vector<double> az(px.size());
      for (std::size_t q = 0; q < px.size(); ++q) az[q] = std::abs(px[q].z);
      std::nth_element(az.begin(), az.begin() + std::ptrdiff_t(az.size() / 2), az.end());
      zscale = std::max(1.0, 1.4826 * az[az.size() / 2]);
    };
    auto normal = [&](bool robust_now, cv::Matx<double, 6, 6>& jtj, cv::Vec<double, 6>& jtr, double& chi2, double& wsum,
                      int& set_aside) {
      jtj = cv::Matx<double, 6, 6>::zeros();
      jtr = cv::Vec<double, 6>::all(0);
      chi2 = wsum = 0;
      set_aside = 0;
      for (const Px& q : px) {
        const double tw = robust_now ? tukey(q.z / zscale) : 1.0;
        if (tw == 0) {
          ++set_aside;
          continue;
        }
        const double wq = tw / q.var;
        const double lx = q.ex * inv_pitch, ly = q.ey * inv_pitch;
        const double amp = p_[2] + p_[4] * lx + p_[5] * ly;
        const double j[6] = {-amp * q.tx, -amp * q.ty, q.t, 1.0, lx * q.t, ly * q.t};
        for (int a = 0; a < P; ++a) {
          jtr[a] += wq * j[a] * q.r;
          for (int b = 0; b <= a; ++b) jtj(a, b) += wq * j[a] * j[b];
        }
        chi2 += wq * q.r * q.r;
        wsum += tw;
      }
      for (int a = 0; a < P; ++a)
        for (int b = 0; b < a; ++b) jtj(b, a) = jtj(a, b);
      for (int a = P; a < 6; ++a) jtj(a, a) = 1;
    };
    bool ok = true;
    cv::Matx<double, 6, 6> jtj;
    cv::Vec<double, 6> jtr;
    double chi2 = 0, wsum = 0;
    int set_aside = 0;
    for (int it = 0; it < 12; ++it) {
      evaluate();
      const bool robust_now = noise.robust && it >= 1;
      // The robust scale settles after a step or two: taken at the first robust ones only.
      if (robust_now && it <= 2) robust_scale();
      normal(robust_now, jtj, jtr, chi2, wsum, set_aside);
      cv::Vec<double, 6> step;
      if (!cv::solve(jtj, jtr, step, cv::DECOMP_CHOLESKY)) {
        ok = false;
        break;
      }
      // At most a fifth of a pitch per step: the template is only known within its cell.
      const double move = std::hypot(step[0], step[1]);
      const double shrink = move > 0.2 * pitch ? 0.2 * pitch / move : 1.0;
      for (int a = 0; a < P; ++a) p_[a] += shrink * step[a];
      if (std::hypot(p_[0], p_[1]) > 0.45 * pitch || !std::isfinite(p_[0] + p_[1] + p_[2] + p_[3])) {
        ok = false;
        break;
      }
      if (it >= (noise.robust ? 3 : 2) && move < 1e-4) break;
    }
    if (!ok || !(p_[2] > 0)) {
      f.amplitude = std::isfinite(p_[2]) ? p_[2] : 0;
      out[k] = f;
      return;
    }
    // The normal matrix at the solution, and the covariance of (dx, dy, a) scaled by the
    // normalised residual (at least 1: the noise model is a floor, not a promise).
    evaluate();
    normal(noise.robust, jtj, jtr, chi2, wsum, set_aside);
    cv::Matx<double, 6, 6> cov;
    if (cv::invert(jtj, cov, cv::DECOMP_CHOLESKY) == 0) {
      out[k] = f;
      return;
    }
    const double dof = std::max(1.0, wsum - P);
    const double s2 = noise.robust ? std::max(1.0, chi2 / dof) : chi2 / dof;
    f.centre = {c0[0] + p_[0], c0[1] + p_[1]};
    f.sigma = std::sqrt(std::max(0.0, 0.5 * (cov(0, 0) + cov(1, 1)) * s2));
    f.amplitude = p_[2];
    f.amplitude_sigma = std::sqrt(std::max(0.0, cov(2, 2) * s2));
    f.background = p_[3];
    f.tilt = {p_[4], p_[5]};
    f.noise = std::sqrt(chi2 / dof);
    f.outliers = double(set_aside) / double(px.size());
    f.converged = std::isfinite(f.sigma) && f.sigma > 0;
    out[k] = f;
  });
  return out;
}

NoiseModel estimate_noise_model(const ImageF& image, const RawLattice& lattice,
                                const std::vector<std::array<int, 2>>& sites, const std::vector<LensFit>& fits,
                                const std::vector<std::uint8_t>& use, const MicroImageTemplate& shape) {
  // (signal, residual) of up to ~1 M pixels from lenses spread over the image.
  std::size_t lenses = 0;
  for (std::size_t k = 0; k < sites.size(); ++k) lenses += use[k] != 0;
  const double per_lens = lattice.px * lattice.py;
  const std::size_t stride = std::max<std::size_t>(1, std::size_t(double(lenses) * per_lens / 1e6));
  std::vector<std::pair<double, double>> samples;
  std::size_t seen = 0;
  for (std::size_t k = 0; k < sites.size(); ++k) {
    if (!use[k] || (seen++ % stride) != 0) continue;
    const LensFit& f = fits[k];
    for_each_cell_pixel(lattice, sites[k][0], sites[k][1], image.width, image.height, [&](int x, int y) {
      const double ex = x - f.centre[0], ey = y - f.centre[1];
      const double t = shape.value(ex, ey);
      const double signal = (f.amplitude + (f.tilt[0] * ex + f.tilt[1] * ey) / lattice.px) * t;
      samples.push_back({signal, image.at(x, y) - f.background - signal});
    });
  }
  NoiseModel model;
  model.robust = true;
  if (samples.size() < 100) {
    model.floor = 1;
    return model;
  }
  std::sort(samples.begin(), samples.end());
  // Twenty bins of equal count; in each, the robust variance of the residuals.
  const int bins = 20;
  std::vector<double> level, variance;
  for (int b = 0; b < bins; ++b) {
    const std::size_t lo = samples.size() * std::size_t(b) / bins, hi = samples.size() * std::size_t(b + 1) / bins;
    if (hi <= lo + 10) continue;
    std::vector<double> ar;
    double mean_level = 0;
    for (std::size_t q = lo; q < hi; ++q) {
      ar.push_back(std::abs(samples[q].second));
      mean_level += samples[q].first;
    }
    std::nth_element(ar.begin(), ar.begin() + std::ptrdiff_t(ar.size() / 2), ar.end());
    const double sigma = 1.4826 * ar[ar.size() / 2];
    level.push_back(std::max(0.0, mean_level / double(hi - lo)));
    variance.push_back(sigma * sigma);
  }
  // Least squares line variance = floor + gain * level, both kept positive.
  double sl = 0, sv = 0, sll = 0, slv = 0;
  const double n = double(level.size());
  for (std::size_t q = 0; q < level.size(); ++q) {
    sl += level[q];
    sv += variance[q];
    sll += level[q] * level[q];
    slv += level[q] * variance[q];
  }
  const double den = n * sll - sl * sl;
  double gain = den > 0 ? (n * slv - sl * sv) / den : 0.0;
  gain = std::max(0.0, gain);
  double floor = (sv - gain * sl) / n;
  const double smallest = *std::min_element(variance.begin(), variance.end());
  floor = std::max(floor, 0.5 * smallest);
  model.floor = std::max(floor, 1e-12);
  model.gain = gain;
  return model;
}

}  // namespace plenopiv::calib
