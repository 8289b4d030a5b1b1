// The plenoptic weighting function of sec 5.2 (eqs 10-13) in raw sensor pixels: the operator's
// geometry and its separable per-slice tables (the kernels that use them: active_set.hpp; the
// explicit reference matrix: explicit_matrix.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::recon {

// How far (pixels) a lens centre may sit from its column's mean x and its row's mean y for the
// separable weights: up to it the weights on the means reconstruct depth better than resampling the
// frames onto an axis-aligned lattice, whose blend across lenses widens every particle's image
// (docs/recon.md, "Rotated, warped and hex arrays").
inline constexpr double kSeparableTolerancePx = 1.0;

// The separable form's view of a rectangular array: one x per lens column and one y per lens row
// (their means), and how far any lens centre departs from them. WeightingOperator takes an array
// only when `separable`; a rotated or warped one is resampled onto an axis-aligned lattice first
// (core/lightfield/lattice_resampling.hpp, chosen by core/process).
struct SeparableLattice {
  std::vector<double> lens_x, lens_y;  // mm on the microlens plane, per lens column / row
  double max_departure_mm = 0;         // of any lens centre from its column's x or row's y
  bool separable(double pixel_pitch_mm) const { return max_departure_mm <= kSeparableTolerancePx * pixel_pitch_mm; }
};
// Reads `lenses` as rows and columns (the layout is not checked: a hex array's shifted rows show
// as a departure of a quarter pitch).
SeparableLattice separable_lattice(const optics::MicrolensArray& lenses);

// A stretch of consecutive pixels with weight along one sensor axis (the pixels one voxel reaches
// behind one microlens, or behind neighbouring lenses where their images touch).
struct Segment {
  int first = 0;
  int length = 0;
  std::size_t offset = 0;  // into the slice's weight table
};

// One voxel's 1-D weights along one sensor axis: its segments, and their extent [first, last].
struct WeightRun {
  int first = 0;
  int last = -1;
  std::size_t segment_begin = 0, segment_end = 0;  // into the slice's segment list
};

// What one depth slice needs: eq 10 for its depth and the 1-D weights of each voxel column/row.
struct SliceTables {
  double z_mm = 0;
  double alpha = 0;               // eq 10c
  double magnification = 0;       // M' = -s'_i / s'_o
  int samples = 0;                // (u, v) plaid samples per aperture axis for this slice
  std::vector<WeightRun> x_runs;  // per voxel x index: weights over sensor columns
  std::vector<WeightRun> y_runs;  // per voxel y index: weights over sensor rows
  std::vector<Segment> x_segments, y_segments;
  std::vector<float> x_table, y_table;
  // The x weights again in the form the kernels' inner loops take: voxel x owns the quads
  // [x_quad_start[x], x_quad_start[x + 1]), each 4 consecutive pixels from x_quad_first with 4
  // weights (zero-padded past a segment's end, shifted left to stay inside the sensor row), so
  // a short segment costs one 4-wide vector operation instead of a loop.
  std::vector<std::size_t> x_quad_start;
  std::vector<int> x_quad_first;
  std::vector<float> x_quad_weights;  // 4 per quad
  // The y weights as quads of 4 consecutive rows, the same way, for the kernels' y stages
  // (zero-padded past a segment's end, never shifted: they weigh rows of a scratch array, and
  // rows past the sensor's last weigh 0).
  std::vector<std::size_t> y_quad_start;
  std::vector<int> y_quad_first;
  std::vector<float> y_quad_weights;  // 4 per quad
};

// One voxel's weights along one axis, ready for a kernel.
struct AxisWeights {
  std::span<const Segment> segments;
  const float* table = nullptr;
  int first = 0;
  int last = -1;
  bool empty() const { return segments.empty(); }
  // Weight of pixel p (0 outside the segments); for tests and masks, not for kernels.
  float at(int p) const;
};

// The depth-dependent part of eq 10 for one slice.
struct SliceOptics {
  double alpha = 0;
  double magnification = 0;
  int samples = 0;
};

// The weighting operator of a camera, a lens array and a voxel grid, in raw sensor pixels.
//
// w_ij = white_i · Ax_j(column_i) · Ay_j(row_i) / n_j, where Ax (Ay) is the sum over the plaid
// aperture samples u (v) of the microlens interpolation weight (eq 11, floor/ceil in lattice
// coordinates) times the pixel interpolation weight of the ray behind that lens (eq 1 inverted),
// and n_j = Σ_i white_i Ax Ay (eq 13). The plaid grid covers the square around the aperture; the
// circular aperture edge is applied by the white image, because behind every lens the pixel
// offset from the spot is exactly -(u, v) f_l / s_i. That makes the 16 coefficients of eq 12
// separable, so W is never stored: two 1-D tables per slice.
//
// Requires a rectangular lens array whose centres share x along columns and y along rows within
// kSeparableTolerancePx (the nominal lattice, or a calibrated one with little rotation); the column
// and row means are used. Hex, rotated or warped arrays are an InputError that says so.
class WeightingOperator {
 public:
  // `white` must have the sensor's size. `angular_sampling` scales the (u, v) samples per aperture
  // axis of every slice (1: sec 5.2's count, see slice_optics; below 1 the rays' spacing on the
  // microlens plane may exceed a lens: cheaper tables, a coarser operator). Throws InputError on a
  // grid inside the main lens's focal length, an unsupported lens array, a white image of the
  // wrong size, or angular_sampling outside (0, 8].
  WeightingOperator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const Grid3& grid,
                    ImageF white, double angular_sampling = 1.0);

  const Grid3& grid() const { return grid_; }
  int image_width() const { return width_; }
  int image_height() const { return height_; }
  std::size_t pixel_count() const { return std::size_t(width_) * height_; }
  const ImageF& white() const { return white_; }
  const SliceTables& slice(int z) const { return slices_[std::size_t(z)]; }
  // Σ_i white_i Ax Ay before eq 13; 0 for a voxel that sees no pixel.
  float normaliser(std::size_t voxel) const { return normaliser_[voxel]; }
  std::span<const float> normalisers() const { return normaliser_; }

  AxisWeights x_weights(int z, int x) const;
  AxisWeights y_weights(int z, int y) const;

  // Dense operators over the whole grid: image = W·volume, volume = Wᵀ·image.
  void project(std::span<const float> volume, std::span<float> image) const;
  void back_project(std::span<const float> image, std::span<float> volume) const;

  // The eq 10 optics of a depth (exposed for the explicit builder and tests).
  SliceOptics slice_optics(double z_mm) const;

  // Everything the kernels share.
  struct Geometry {
    double s_o = 0, s_i = 0, f_main = 0, f_lens = 0, aperture = 0, pixel_pitch = 0;
    int nominal_samples = 0;
    double angular_sampling = 1.0;  // scale of the per-slice sample count
    double min_pitch = 0;
    std::vector<double> lens_x;          // lens centres along x (one per lens column), increasing
    std::vector<double> lens_y;          // along y (one per lens row), increasing
    double max_centre_deviation_mm = 0;  // of any lens from its column/row mean
  };
  const Geometry& geometry() const { return geo_; }
  const optics::SensorSpec& sensor() const { return sensor_; }  // with its optical axis

  // The operator as bytes (everything the constructor computed: tables, normalisers, white
  // image, geometry), appended to `out`, and back: a cache of operators (core/process) keeps
  // them between runs. The layout is this build's; a reader of another layout or of damaged
  // bytes gets an InputError, never a wrong operator (the caller keys and checksums the bytes).
  void serialize(std::string& out) const;
  static constexpr std::uint32_t kBytesFormat = 1;  // changes with serialize's layout
  static WeightingOperator deserialize(std::string_view bytes);
  // Bytes held by the tables, normalisers and white image.
  std::size_t bytes() const;

 private:
  WeightingOperator() = default;  // for deserialize
  // The construction, step by step: the inputs checked (weights.cpp), the geometry read from the
  // camera and lens array (weights.cpp), the 1-D tables of every slice and the eq 13 normalisers
  // (slice_tables.cpp).
  void check_inputs(const optics::MicrolensArray& lenses, double angular_sampling) const;
  void read_geometry(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, double angular_sampling);
  void build_slice_tables();
  void compute_normalisers();

  Grid3 grid_;
  int width_ = 0, height_ = 0;
  optics::SensorSpec sensor_;
  ImageF white_;
  Geometry geo_;
  std::vector<SliceTables> slices_;
  HugePageVector<float> normaliser_;  // one per voxel of the grid: on huge pages
};

}  // namespace plenopiv::recon
