// The weighting operator's geometry (eq 10 per depth, the separable lattice) and its dense
// projection and back-projection; the tables themselves are built in slice_tables.cpp.
#include "core/recon/weights.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "core/base/errors.hpp"
#include "core/recon/active_set.hpp"
#include "core/recon/kernels.hpp"

namespace plenopiv::recon {

SeparableLattice separable_lattice(const optics::MicrolensArray& lenses) {
  const optics::Lattice& lat = lenses.lattice;
  if (lenses.centres_mm.size() != std::size_t(lat.count()))
    throw InputError("microlens array: " + std::to_string(lenses.centres_mm.size()) + " centres for " +
                     std::to_string(lat.count()) + " lenses");
  SeparableLattice out;
  // Separability: one x per lens column and one y per lens row (their means). A measured array
  // may scatter about them by a fraction of a pixel; a rotated or warped one cannot be separated.
  out.lens_x.assign(std::size_t(lat.count_x), 0.0);
  out.lens_y.assign(std::size_t(lat.count_y), 0.0);
  // Means as the first lens plus the mean departure from it, so an exact lattice stays exact.
  for (int j = 0; j < lat.count_y; ++j) {
    for (int i = 0; i < lat.count_x; ++i) {
      out.lens_x[std::size_t(i)] += (lenses.centre(i, j)[0] - lenses.centre(i, 0)[0]) / lat.count_y;
      out.lens_y[std::size_t(j)] += (lenses.centre(i, j)[1] - lenses.centre(0, j)[1]) / lat.count_x;
    }
  }
  for (int i = 0; i < lat.count_x; ++i) out.lens_x[std::size_t(i)] += lenses.centre(i, 0)[0];
  for (int j = 0; j < lat.count_y; ++j) out.lens_y[std::size_t(j)] += lenses.centre(0, j)[1];
  for (int j = 0; j < lat.count_y; ++j) {
    for (int i = 0; i < lat.count_x; ++i) {
      const double dev = std::max(std::abs(lenses.centre(i, j)[0] - out.lens_x[std::size_t(i)]),
                                  std::abs(lenses.centre(i, j)[1] - out.lens_y[std::size_t(j)]));
      out.max_departure_mm = std::max(out.max_departure_mm, dev);
    }
  }
  return out;
}

WeightingOperator::WeightingOperator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                                     const Grid3& grid, ImageF white, double angular_sampling)
    : grid_(grid),
      width_(camera.sensor().width_px),
      height_(camera.sensor().height_px),
      sensor_(camera.sensor()),
      white_(std::move(white)) {
  check_inputs(lenses, angular_sampling);
  read_geometry(camera, lenses, angular_sampling);
  build_slice_tables();
  compute_normalisers();
}

void WeightingOperator::check_inputs(const optics::MicrolensArray& lenses, double angular_sampling) const {
  if (white_.width != width_ || white_.height != height_) {
    throw InputError("white image: " + std::to_string(white_.width) + " x " + std::to_string(white_.height) +
                     " px, the sensor is " + std::to_string(width_) + " x " + std::to_string(height_));
  }
  if (width_ < kernels::kQuad) throw InputError("sensor: the reconstruction needs at least 4 pixels per row");
  if (!(angular_sampling > 0 && angular_sampling <= 8)) {
    throw InputError("angular_sampling: must be in (0, 8], got " + std::to_string(angular_sampling));
  }
  for (int a = 0; a < 3; ++a) {
    if (grid_.shape[a] <= 0 || !(grid_.spacing_mm[a] > 0)) {
      throw InputError("volume grid: every axis needs at least one voxel and a positive spacing");
    }
  }
  const optics::Lattice& lat = lenses.lattice;
  if (lat.layout != optics::LensletLayout::rect) {
    throw InputError(
        "microlens array: the reconstruction needs a rectangular lattice (hex arrays are "
        "not supported yet)");
  }
  if (lat.count_x < 2 || lat.count_y < 2 || lenses.centres_mm.size() != std::size_t(lat.count())) {
    throw InputError("microlens array: needs at least 2 x 2 lenses and one centre per lens");
  }
}

void WeightingOperator::read_geometry(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                                      double angular_sampling) {
  geo_.s_o = camera.object_distance_mm();
  geo_.s_i = camera.image_distance_mm();
  geo_.f_main = camera.main_lens().focal_length_mm;
  geo_.f_lens = camera.microlens().focal_length_mm;
  geo_.aperture = camera.aperture_diameter_mm();
  geo_.pixel_pitch = camera.sensor().pixel_pitch_mm;
  geo_.nominal_samples = std::max(2, int(std::ceil(camera.microlens_image_diameter_px() - 1e-9)));
  geo_.angular_sampling = angular_sampling;
  SeparableLattice sep = separable_lattice(lenses);
  geo_.lens_x = std::move(sep.lens_x);
  geo_.lens_y = std::move(sep.lens_y);
  geo_.max_centre_deviation_mm = sep.max_departure_mm;
  if (!sep.separable(geo_.pixel_pitch)) {
    throw InputError("microlens array: lens centres leave their lattice columns/rows by up to " +
                     std::to_string(geo_.max_centre_deviation_mm / geo_.pixel_pitch) +
                     " px (rotated or warped array); the separable weights allow " +
                     std::to_string(kSeparableTolerancePx) + " px");
  }
  geo_.min_pitch = 1e300;
  for (std::size_t i = 1; i < geo_.lens_x.size(); ++i)
    geo_.min_pitch = std::min(geo_.min_pitch, geo_.lens_x[i] - geo_.lens_x[i - 1]);
  for (std::size_t j = 1; j < geo_.lens_y.size(); ++j)
    geo_.min_pitch = std::min(geo_.min_pitch, geo_.lens_y[j] - geo_.lens_y[j - 1]);
  if (!(geo_.min_pitch > 0)) throw InputError("microlens array: centres must increase along rows and columns");
}

SliceOptics WeightingOperator::slice_optics(double z_mm) const {
  // Eq 10 with s'_o = s_o + z_o (DESIGN.md: the printed s_i + z_o holds only at M = -1).
  const double so = geo_.s_o + z_mm;
  if (!(so > geo_.f_main * (1 + 1e-9))) {
    throw InputError("volume grid: depth z = " + std::to_string(z_mm) +
                     " mm lies at or inside the main lens's focal length; no real image forms there");
  }
  const double si = geo_.f_main * so / (so - geo_.f_main);
  SliceOptics o;
  o.alpha = si / geo_.s_i;
  o.magnification = -si / so;
  // Sec 5.2: enough rays that their spacing on the microlens plane stays under one microlens,
  // and never fewer than the nominal angular sampling (pixels across a microlens image); then
  // scaled by the operator's angular_sampling (a time-against-accuracy knob), at least 2.
  const double spread = geo_.aperture * std::abs(1.0 - 1.0 / o.alpha);
  const int sec52 = std::max(geo_.nominal_samples, int(std::floor(spread / geo_.min_pitch)) + 1);
  o.samples = std::max(2, int(std::ceil(geo_.angular_sampling * sec52 - 1e-9)));
  return o;
}

namespace {
AxisWeights axis_weights(const WeightRun& r, const std::vector<Segment>& segments, const std::vector<float>& table) {
  AxisWeights w;
  w.segments = {segments.data() + r.segment_begin, r.segment_end - r.segment_begin};
  w.table = table.data();
  w.first = r.first;
  w.last = r.last;
  return w;
}
}  // namespace

float AxisWeights::at(int p) const {
  for (const Segment& s : segments) {
    if (p >= s.first && p < s.first + s.length) return table[s.offset + std::size_t(p - s.first)];
  }
  return 0.f;
}

AxisWeights WeightingOperator::x_weights(int z, int x) const {
  const SliceTables& t = slices_[std::size_t(z)];
  return axis_weights(t.x_runs[std::size_t(x)], t.x_segments, t.x_table);
}
AxisWeights WeightingOperator::y_weights(int z, int y) const {
  const SliceTables& t = slices_[std::size_t(z)];
  return axis_weights(t.y_runs[std::size_t(y)], t.y_segments, t.y_table);
}

void WeightingOperator::project(std::span<const float> volume, std::span<float> image) const {
  if (volume.size() != grid_.count() || image.size() != pixel_count()) {
    throw InputError("project: volume or image size does not match the operator");
  }
  ActiveSet::all(*this).project(*this, volume, image);
}

void WeightingOperator::back_project(std::span<const float> image, std::span<float> volume) const {
  if (volume.size() != grid_.count() || image.size() != pixel_count()) {
    throw InputError("back_project: volume or image size does not match the operator");
  }
  ActiveSet::all(*this).back_project(*this, image, volume);
}

}  // namespace plenopiv::recon
