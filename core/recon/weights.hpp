// The plenoptic weighting function of sec 5.2 (eqs 10-13) in raw sensor pixels: separable
// per-slice tables, the matrix-free projection W·E and back-projection Wᵀ·r, and the explicit
// sparse matrix built literally ray by ray as the reference for small cases.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "core/base/big_buffer.hpp"
#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::recon {

// The white-image correction of fig 15 from the camera model: per pixel, the fraction of its area
// inside the disk of diameter CameraModel::microlens_image_diameter_px() around the spot of each
// lens (1 inside a microlens image, 0 outside). Calibration later provides the measured one.
ImageF geometric_white_image(const optics::CameraModel& camera, const optics::MicrolensArray& lenses);

// How far (pixels) a lens centre may sit from its column's mean x and its row's mean y for the
// separable weights.
inline constexpr double kSeparableTolerancePx = 0.25;

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
  double alpha = 0;            // eq 10c
  double magnification = 0;   // M' = -s'_i / s'_o
  int samples = 0;             // (u, v) plaid samples per aperture axis for this slice
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
// 0.25 px (the nominal lattice, or a calibrated one without measurable rotation); the column and
// row means are used. Hex, rotated or warped arrays are an InputError that says so.
class WeightingOperator {
 public:
  // `white` must have the sensor's size. `angular_sampling` scales the (u, v) samples per aperture
  // axis of every slice (1: sec 5.2's count, see slice_optics; below 1 the rays' spacing on the
  // microlens plane may exceed a lens: cheaper tables, a coarser operator). Throws InputError on a
  // grid inside the main lens's focal length, an unsupported lens array, a white image of the
  // wrong size, or angular_sampling outside (0, 8].
  WeightingOperator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                    const Grid3& grid, ImageF white, double angular_sampling = 1.0);

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
    std::vector<double> lens_x;  // lens centres along x (one per lens column), increasing
    std::vector<double> lens_y;  // along y (one per lens row), increasing
    double max_centre_deviation_mm = 0;  // of any lens from its column/row mean
  };
  const Geometry& geometry() const { return geo_; }
  const optics::SensorSpec& sensor() const { return sensor_; }  // with its optical axis

 private:
  Grid3 grid_;
  int width_ = 0, height_ = 0;
  optics::SensorSpec sensor_;
  ImageF white_;
  Geometry geo_;
  std::vector<SliceTables> slices_;
  std::vector<float> normaliser_;
};

// A set of voxels that take part in a reconstruction (sorted flat indices), grouped by voxel
// column (z, x) and by bands of sensor rows for the two-stage separable kernels.
//
// Per column the kernels factor the weights: projection forms G(row) = Σ_y Ay_y(row) E_y / n_y
// over the column's voxels, then adds G(row) · Ax(col) once per row; back-projection forms
// B(row) = Σ_col Ax(col) r(row, col) once per row, then Σ_row Ay_y(row) B(row) per voxel. That
// costs (rows any voxel of the column reaches) x |Ax| instead of Σ_voxels |Ay| x |Ax|: never
// more (a column with one voxel is the per-voxel form); 2x less on the 0.5 ppm benchmarks.
// Both walk the sensor in bands of rows and the voxels in strips of x so that the pixels and
// weights they touch stay in cache: projection band by band (a band owns its rows: no atomics),
// back-projection strip by strip (a strip owns its voxels, each summed band after band). Within
// a band the x stages take a few dozen columns at a time, 16 rows at a time, so the pixels those
// columns share stay in L1. They work on the image in row lanes (each block of 16 rows stored
// column by column), so one x weight meets 16 rows in one vector operation; every pixel and voxel
// still gets its sums in the same order as row by row.
class ActiveSet {
 public:
  // `voxels`: flat indices into the operator's grid, strictly increasing (InputError otherwise).
  ActiveSet(const WeightingOperator& op, std::vector<std::uint32_t> voxels);
  static ActiveSet all(const WeightingOperator& op);

  const std::vector<std::uint32_t>& voxels() const { return voxels_; }
  std::size_t size() const { return voxels_.size(); }

  // Buffers a pass needs (E / n in column order, the per-voxel sums), kept by whoever runs many
  // passes (MART) so that a pass neither allocates nor page-faults them (~36 MB on the paper case).
  struct Workspace {
    BigBuffer<float> scaled;
    BigBuffer<double> sums;
    // The kernels' x stages take images in row lanes (blocks of 16 rows stored column by
    // column): one band per thread for a projection, the whole images for a back-projection.
    BigBuffer<float> band_lanes, image_lanes;
  };
  // Called once per band of sensor rows, pixels [first_pixel, end_pixel), as soon as a projection
  // has finished them, on the thread that computed them: per-pixel work on the projection while
  // the band is in cache. Bands are numbered 0..band_count() - 1 and cover the image in order.
  using BandDone = std::function<void(int band, std::size_t first_pixel, std::size_t end_pixel)>;
  int band_count() const { return bands_; }

  // image = W·values (values per active voxel, image of the sensor's size, overwritten).
  void project(const WeightingOperator& op, std::span<const float> values, std::span<float> image,
               Workspace* workspace = nullptr, const BandDone& band_done = {}) const;
  // values = Wᵀ·image for the active voxels. The image must be finite: the 4-pixel quads also
  // read a few pixels beside a voxel's segments, with weight 0.
  void back_project(const WeightingOperator& op, std::span<const float> image,
                    std::span<float> values) const;
  // The same for an image already multiplied pixel by pixel by the white correction (saves a
  // pass and a buffer inside MART's loop).
  void back_project_whitened(const WeightingOperator& op, std::span<const float> whitened_image,
                             std::span<float> values, Workspace* workspace = nullptr) const;
  // Two whitened images in one walk (MLOS needs the lit mask's and ln I's): each result has the
  // same bits as its own back_project_whitened; the bookkeeping is paid once.
  void back_project_whitened(const WeightingOperator& op, std::span<const float> whitened_a,
                             std::span<float> values_a, std::span<const float> whitened_b,
                             std::span<float> values_b, Workspace* workspace = nullptr) const;

 private:
  // One voxel column (z, x) of the set: its voxels are order_[begin, end), y increasing.
  struct Column {
    int z = 0, x = 0;
    std::uint32_t begin = 0, end = 0;
  };
  // One voxel of a column in one band: its y quads that overlap the band (into its slice's
  // y_quad_first / y_quad_weights).
  struct BandEntry {  // no initialisers: millions are allocated, then each written once
    std::uint32_t position;  // in order_
    std::uint32_t quad_begin;
    std::uint32_t quad_count;
  };
  // Sensor rows per band. Few bands per voxel keep the per-band bookkeeping small; the pixels a
  // strip of voxel x reaches in one band (~0.6 MB on the paper sensor) stay in L2. Measured on
  // the paper case (bench_recon paper 0.5 0 0.9 2, CPU time): 128 rows 1.12x the time of 256,
  // 512 no better (and fewer bands to share out).
  static constexpr int kBandRows = 256;
  static constexpr int kRowWords = kBandRows / 64;
  // One column's share of one band, as the kernels visit it: its entries and, as bits, the band's
  // rows its voxels reach (the rows the two-stage kernels touch).
  struct Visit {  // no initialisers, as BandEntry
    std::uint32_t column;  // into columns_
    std::uint32_t entry_begin, entry_end;  // into entries_
    std::array<std::uint64_t, kRowWords> rows;  // bit r: row r0 + r of the band
  };

  std::vector<std::uint32_t> voxels_;
  // Voxels with a positive normaliser, in the kernels' visiting order (strip, depth, x, then y
  // increasing): position in voxels_ and n. A pass reads and writes its per-voxel arrays front to
  // back, and each strip owns one contiguous range of them.
  BigBuffer<std::uint32_t> order_;
  BigBuffer<float> order_normaliser_;
  std::vector<Column> columns_;  // in the same order
  // Voxel x per strip: within a band the kernels walk strip by strip, depth by depth, x by x, so
  // the y weights of one depth serve the whole strip and the pixels under the strip stay cached.
  int strip_x_ = 1;
  int strips_ = 0;
  int bands_ = 0;
  std::vector<int> band_order_, strip_order_;  // the order passes hand them out: costliest first
  std::vector<std::uint32_t> strip_columns_;  // strip s owns columns_[strip_columns_[s], strip_columns_[s + 1])
  // The visits of band b and strip s are visits_[visit_start_[b * strips_ + s], visit_start_[b * strips_ + s + 1]);
  // visits and their entries lie in the kernels' reading order (band, strip, depth, x), so a
  // pass streams through both.
  std::vector<std::size_t> visit_start_;
  BigBuffer<Visit> visits_;
  BigBuffer<BandEntry> entries_;

  // Back-projection of N whitened images at once (N = 1 or 2).
  template <std::size_t N>
  void back_project_images(const WeightingOperator& op, const std::array<const float*, N>& images,
                           const std::array<float*, N>& values, Workspace& workspace) const;
};

// Compressed sparse rows: the explicit matrix (rows = sensor pixels, columns = voxels).
struct SparseMatrix {
  std::size_t rows = 0, cols = 0;
  std::vector<std::size_t> row_start;  // rows + 1
  std::vector<std::uint32_t> col_index;
  std::vector<float> values;

  void multiply(std::span<const float> x, std::span<float> y) const;            // y = A x
  void multiply_transpose(std::span<const float> y, std::span<float> x) const;  // x = Aᵀ y
  std::size_t nonzeros() const { return values.size(); }
};

// The reference: for every voxel, for every plaid (u, v) sample, the 16 coefficients of eq 12
// (4 lenses x 4 pixels) times the white image, normalised per voxel (eq 13). For small cases.
SparseMatrix build_explicit_matrix(const WeightingOperator& op);

}  // namespace plenopiv::recon
