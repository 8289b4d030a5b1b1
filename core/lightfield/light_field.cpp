// The light field of a raw plenoptic image: per-pixel (x, y, u, v) and the rectified L(lx, ly, u, v).
#include "core/lightfield/light_field.hpp"

#include <tbb/parallel_for.h>

#include <cmath>
#include <string>

#include "core/base/errors.hpp"
#include "core/calib/calibration.hpp"

namespace plenopiv::lightfield {
namespace {

void check_image(const optics::SensorSpec& s, const ImageF& image, const std::string& what) {
  if (image.width != s.width_px || image.height != s.height_px) {
    throw InputError(what + " is " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                     " pixels, the camera file's sensor is " + std::to_string(s.width_px) + " x " +
                     std::to_string(s.height_px));
  }
  for (std::size_t k = 0; k < image.size(); ++k) {
    if (!std::isfinite(image.pixels[k]) || image.pixels[k] < 0) {
      throw InputError(what + ": pixel (" + std::to_string(k % image.width) + ", " + std::to_string(k / image.width) +
                       ") is not a finite, non-negative value");
    }
  }
}

// The array comes from the calibration (or the camera's nominal lattice): its lens count is its
// own, not necessarily the camera file's (arrays overfill the sensor; counts are optional).
void check_lenses(const optics::CameraModel& camera, const optics::MicrolensArray& lenses) {
  const auto& l = lenses.lattice;
  if (l.count_x < 1 || l.count_y < 1 || lenses.centres_mm.size() != std::size_t(l.count())) {
    throw InputError("microlens array of " + std::to_string(l.count_x) + " x " + std::to_string(l.count_y) +
                     " lenses has " + std::to_string(lenses.centres_mm.size()) + " centres");
  }
  if (l.layout != camera.microlens().layout) {
    throw InputError(std::string("microlens array: ") + optics::to_string(l.layout) +
                     " lenses, the camera file's are " + optics::to_string(camera.microlens().layout));
  }
}

// Bilinear interpolation at continuous pixel coordinates (integers are pixel centres); false when
// the four pixels are not all on the sensor.
bool bilinear(const ImageF& image, double col, double row, float& out) {
  const double fc = std::floor(col), fr = std::floor(row);
  const int c0 = int(fc), r0 = int(fr);
  if (c0 < 0 || r0 < 0 || c0 + 1 >= image.width || r0 + 1 >= image.height) return false;
  const float tc = float(col - fc), tr = float(row - fr);
  const float* a = &image.pixels[std::size_t(r0) * image.width + c0];
  const float* b = a + image.width;
  out = (1 - tr) * ((1 - tc) * a[0] + tc * a[1]) + tr * ((1 - tc) * b[0] + tc * b[1]);
  return true;
}

}  // namespace

PixelRays pixel_rays(const optics::CameraModel& camera, const optics::MicrolensArray& lenses) {
  check_lenses(camera, lenses);
  const auto& s = camera.sensor();
  const double s_i = camera.image_distance_mm(), f_l = camera.microlens().focal_length_mm;
  optics::Lattice spot_lattice = lenses.lattice;
  spot_lattice.pitch_x_mm = optics::lens_centre_to_spot_mm(spot_lattice.pitch_x_mm, s_i, f_l);
  spot_lattice.pitch_y_mm = optics::lens_centre_to_spot_mm(spot_lattice.pitch_y_mm, s_i, f_l);
  spot_lattice.offset_x_mm = optics::lens_centre_to_spot_mm(spot_lattice.offset_x_mm, s_i, f_l);
  spot_lattice.offset_y_mm = optics::lens_centre_to_spot_mm(spot_lattice.offset_y_mm, s_i, f_l);
  std::vector<std::array<double, 2>> spots_mm(lenses.centres_mm.size()), spots_px(lenses.centres_mm.size());
  for (std::size_t k = 0; k < spots_mm.size(); ++k) {
    spots_mm[k] = {optics::lens_centre_to_spot_mm(lenses.centres_mm[k][0], s_i, f_l),
                   optics::lens_centre_to_spot_mm(lenses.centres_mm[k][1], s_i, f_l)};
    spots_px[k] = {optics::sensor_mm_to_column(s, spots_mm[k][0]), optics::sensor_mm_to_row(s, spots_mm[k][1])};
  }
  PixelRays rays;
  rays.width = s.width_px;
  rays.height = s.height_px;
  rays.lens = calib::pixel_lens_map(s, spot_lattice, spots_px);
  const std::size_t n = rays.lens.size();
  rays.x_mm.assign(n, 0.0f);
  rays.y_mm.assign(n, 0.0f);
  rays.u_mm.assign(n, 0.0f);
  rays.v_mm.assign(n, 0.0f);
  tbb::parallel_for(0, s.height_px, [&](int row) {
    for (int col = 0; col < s.width_px; ++col) {
      const std::size_t k = std::size_t(row) * s.width_px + col;
      const int id = rays.lens[k];
      if (id < 0) continue;
      rays.x_mm[k] = float(lenses.centres_mm[id][0]);
      rays.y_mm[k] = float(lenses.centres_mm[id][1]);
      rays.u_mm[k] =
          float(optics::aperture_from_sensor_mm(optics::column_to_sensor_mm(s, col), spots_mm[id][0], s_i, f_l));
      rays.v_mm[k] =
          float(optics::aperture_from_sensor_mm(optics::row_to_sensor_mm(s, row), spots_mm[id][1], s_i, f_l));
    }
  });
  return rays;
}

ApertureSampling ApertureSampling::for_camera(const optics::CameraModel& camera, int n) {
  if (n <= 0) n = std::max(1, int(std::lround(camera.microlens_image_diameter_px())));
  ApertureSampling a;
  a.n_u = a.n_v = n;
  a.du_mm = a.dv_mm = camera.aperture_diameter_mm() / n;
  return a;
}

LightField rectify(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& raw,
                   const ImageF* white, const RectifyOptions& options) {
  check_lenses(camera, lenses);
  check_image(camera.sensor(), raw, "raw image");
  if (white) check_image(camera.sensor(), *white, "white correction");
  LightField field;
  field.lenses = lenses;
  field.sampling = options.sampling.n_u > 0 ? options.sampling : ApertureSampling::for_camera(camera);
  const ApertureSampling& a = field.sampling;
  if (a.n_v <= 0 || !(a.du_mm > 0) || !(a.dv_mm > 0)) {
    throw InputError("aperture sampling: n_u, n_v must be positive and du, dv > 0");
  }
  const auto& s = camera.sensor();
  const double s_i = camera.image_distance_mm(), f_l = camera.microlens().focal_length_mm;
  const double radius2 = 0.25 * camera.aperture_diameter_mm() * camera.aperture_diameter_mm();
  const int nx = field.nx(), ny = field.ny();
  const std::size_t total = std::size_t(a.n_u) * a.n_v * nx * ny;
  field.values.assign(total, 0.0f);
  field.valid.assign(total, 0);
  tbb::parallel_for(0, a.n_v * a.n_u, [&](int uv) {
    const int iv = uv / a.n_u, iu = uv % a.n_u;
    const double u = a.u(iu), v = a.v(iv);
    if (u * u + v * v > radius2) return;
    // Eq 1 inverted: the sensor point that sees aperture point (u, v) through a lens.
    const double shift_x = u * f_l / s_i, shift_y = v * f_l / s_i;
    for (int ly = 0; ly < ny; ++ly) {
      for (int lx = 0; lx < nx; ++lx) {
        const auto& c = lenses.centre(lx, ly);
        const double col = optics::sensor_mm_to_column(s, optics::lens_centre_to_spot_mm(c[0], s_i, f_l) - shift_x);
        const double row = optics::sensor_mm_to_row(s, optics::lens_centre_to_spot_mm(c[1], s_i, f_l) - shift_y);
        float value = 0, w = 1;
        if (!bilinear(raw, col, row, value)) continue;
        if (white && (!bilinear(*white, col, row, w) || w < options.min_white)) continue;
        const std::size_t k = field.index(lx, ly, iu, iv);
        field.values[k] = value / w;
        field.valid[k] = 1;
      }
    }
  });
  return field;
}

LatticeInterpolator::LatticeInterpolator(const optics::Lattice& lattice)
    : lattice_(lattice), cos_(std::cos(lattice.rotation_rad)), sin_(std::sin(lattice.rotation_rad)) {}

int LatticeInterpolator::weights(double x_mm, double y_mm, std::array<int, 4>& lens,
                                 std::array<float, 4>& weight) const {
  const auto& l = lattice_;
  const auto d = to_lattice(x_mm - l.offset_x_mm, y_mm - l.offset_y_mm);
  return weights_at(d[0] + 0.5 * (l.count_x - 1), d[1] + 0.5 * (l.count_y - 1), lens, weight);
}

std::array<double, 2> LatticeInterpolator::to_lattice(double dx, double dy) const {
  return {(cos_ * dx - sin_ * dy) / lattice_.pitch_x_mm, (sin_ * dx + cos_ * dy) / lattice_.pitch_y_mm};
}

int LatticeInterpolator::weights_at(double a, double b, std::array<int, 4>& lens, std::array<float, 4>& weight) const {
  const auto& l = lattice_;
  const bool hex = l.layout == optics::LensletLayout::hex;
  const double fb = std::floor(b);
  const int j0 = int(fb);
  const double tj = b - fb;
  int n = 0;
  for (int r = 0; r < 2; ++r) {
    const int j = j0 + r;
    const double wj = r == 0 ? 1 - tj : tj;
    if (j < 0 || j >= l.count_y || wj == 0) continue;
    const double i_cont = a - (hex ? ((j & 1) ? 0.25 : -0.25) : 0.0);
    const double fi = std::floor(i_cont);
    const int i0 = int(fi);
    const double ti = i_cont - fi;
    for (int q = 0; q < 2; ++q) {
      const int i = i0 + q;
      const double wi = q == 0 ? 1 - ti : ti;
      if (i < 0 || i >= l.count_x || wi == 0) continue;
      lens[n] = j * l.count_x + i;
      weight[n] = float(wi * wj);
      ++n;
    }
  }
  return n;
}

}  // namespace plenopiv::lightfield
