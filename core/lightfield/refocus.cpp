// Computational refocusing (eqs 2-4) and perspective views (sec 3.4).
#include "core/lightfield/refocus.hpp"

#include <tbb/parallel_for.h>

#include <cmath>
#include <string>

#include "core/base/errors.hpp"

namespace plenopiv::lightfield {

double alpha_for_depth(const optics::CameraModel& camera, double z_mm) {
  const double f = camera.main_lens().focal_length_mm;
  const double s_o = camera.object_distance_mm() + z_mm;
  if (!(s_o > f)) {
    throw InputError("depth z = " + std::to_string(z_mm) + " mm puts the object " + std::to_string(s_o) +
                     " mm from the main lens, not beyond its focal length " + std::to_string(f) + " mm");
  }
  return f * s_o / (s_o - f) / camera.image_distance_mm();
}

double depth_for_alpha(const optics::CameraModel& camera, double alpha) {
  const double f = camera.main_lens().focal_length_mm;
  const double s_i = alpha * camera.image_distance_mm();
  if (!(s_i > f)) return std::nan("");
  return f * s_i / (s_i - f) - camera.object_distance_mm();
}

double focus_measure(const ImageF& image) {
  double s1 = 0, s2 = 0;
  for (float v : image.pixels) {
    s1 += v;
    s2 += double(v) * v;
  }
  return s1 > 0 ? s2 / (s1 * s1) : 0;
}

double sharpest_depth_mm(const LightField& field, const optics::CameraModel& camera, double z_min_mm, double z_max_mm,
                         double step_mm) {
  if (!(step_mm > 0) || !(z_max_mm >= z_min_mm)) {
    throw InputError("depth from focus: need step > 0 and z_max >= z_min, got " + std::to_string(z_min_mm) + ".." +
                     std::to_string(z_max_mm) + " step " + std::to_string(step_mm));
  }
  double best_z = z_min_mm, best = -1;
  for (int k = 0; z_min_mm + k * step_mm <= z_max_mm + 1e-9 * step_mm; ++k) {
    const double z = z_min_mm + k * step_mm;
    const double m = focus_measure(refocus(field, alpha_for_depth(camera, z)));
    if (m > best) {
      best = m;
      best_z = z;
    }
  }
  return best_z;
}

ImageF refocus(const LightField& field, double alpha) {
  if (!(alpha > 0) || !std::isfinite(alpha))
    throw InputError("refocus: alpha must be positive, got " + std::to_string(alpha));
  const int nx = field.nx(), ny = field.ny();
  const ApertureSampling& a = field.sampling;
  const LatticeInterpolator interp(field.lenses.lattice);
  const double k = 1 - 1 / alpha;
  // Eq 2 shifts every output pixel of one view by the same vector u (1 - 1/alpha): in lattice
  // coordinates a constant (da, db) per view, so no trigonometry in the loop.
  std::vector<std::array<double, 2>> shift(std::size_t(a.n_u) * a.n_v);
  for (int iv = 0; iv < a.n_v; ++iv) {
    for (int iu = 0; iu < a.n_u; ++iu)
      shift[std::size_t(iv) * a.n_u + iu] = interp.to_lattice(a.u(iu) * k, a.v(iv) * k);
  }
  const bool hex = field.lenses.lattice.layout == optics::LensletLayout::hex;
  ImageF out(nx, ny, 0.0f);
  tbb::parallel_for(0, ny, [&](int j) {
    std::array<int, 4> lens;
    std::array<float, 4> w;
    const double row_shift = hex ? ((j & 1) ? 0.25 : -0.25) : 0.0;
    std::vector<double> acc(nx, 0.0), wsum(nx, 0.0);
    for (std::size_t view = 0; view < shift.size(); ++view) {
      const std::uint8_t* valid = &field.valid[view * nx * ny];
      const float* values = &field.values[view * nx * ny];
      for (int i = 0; i < nx; ++i) {
        const int n = interp.weights_at(i + row_shift + shift[view][0], j + shift[view][1], lens, w);
        for (int q = 0; q < n; ++q) {
          if (!valid[lens[q]]) continue;
          acc[i] += double(w[q]) * values[lens[q]];
          wsum[i] += w[q];
        }
      }
    }
    for (int i = 0; i < nx; ++i) out.at(i, j) = wsum[i] > 0 ? float(acc[i] / wsum[i]) : 0.0f;
  });
  return out;
}

std::vector<ImageF> focal_stack(const LightField& field, const std::vector<double>& alphas) {
  std::vector<ImageF> stack;
  stack.reserve(alphas.size());
  for (double alpha : alphas) stack.push_back(refocus(field, alpha));
  return stack;
}

ImageF perspective_view(const LightField& field, double u_mm, double v_mm) {
  const ApertureSampling& a = field.sampling;
  const double ku = u_mm / a.du_mm + 0.5 * (a.n_u - 1), kv = v_mm / a.dv_mm + 0.5 * (a.n_v - 1);
  if (!(ku >= 0 && kv >= 0 && ku <= a.n_u - 1 && kv <= a.n_v - 1)) {
    throw InputError("perspective: (u, v) = (" + std::to_string(u_mm) + ", " + std::to_string(v_mm) +
                     ") mm lies outside the sampled aperture, |u| <= " + std::to_string(a.u(a.n_u - 1)) +
                     " mm, |v| <= " + std::to_string(a.v(a.n_v - 1)) + " mm");
  }
  const int u0 = std::min(int(ku), a.n_u - 1), v0 = std::min(int(kv), a.n_v - 1);
  const double tu = ku - u0, tv = kv - v0;
  const int nx = field.nx(), ny = field.ny();
  ImageF out(nx, ny, 0.0f);
  tbb::parallel_for(0, ny, [&](int j) {
    for (int i = 0; i < nx; ++i) {
      double acc = 0, wsum = 0;
      for (int dv = 0; dv < 2; ++dv) {
        for (int du = 0; du < 2; ++du) {
          const double w = (du ? tu : 1 - tu) * (dv ? tv : 1 - tv);
          if (w == 0 || u0 + du >= a.n_u || v0 + dv >= a.n_v) continue;
          const std::size_t k = field.index(i, j, u0 + du, v0 + dv);
          if (!field.valid[k]) continue;
          acc += w * field.values[k];
          wsum += w;
        }
      }
      out.at(i, j) = wsum > 0 ? float(acc / wsum) : 0.0f;
    }
  });
  return out;
}

}  // namespace plenopiv::lightfield
