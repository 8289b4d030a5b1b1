// The voxels a reconstruction solves, laid out for the two-stage separable kernels, and the
// matrix-free projection W·E and back-projection Wᵀ·r over them.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "core/base/big_buffer.hpp"
#include "core/recon/kernels.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::recon {

// A set of voxels that take part in a reconstruction (sorted flat indices), grouped by voxel
// column (z, x) and by bands of sensor rows for the two-stage separable kernels.
//
// Per column the kernels factor the weights: projection forms G(row) = Σ_y Ay_y(row) E_y / n_y
// over the column's voxels, then adds G(row) · Ax(col) once per row; back-projection forms
// B(row) = Σ_col Ax(col) r(row, col) once per row, then Σ_row Ay_y(row) B(row) per voxel. That
// costs (rows any voxel of the column reaches) x |Ax| instead of Σ_voxels |Ay| x |Ax|: never
// more (a column with one voxel is the per-voxel form), less the more the column's voxels
// overlap on the sensor. Both walk the sensor in bands of rows and the voxels in strips of x so
// that the pixels and weights they touch stay in cache: projection band by band (a band owns
// its rows: no atomics), back-projection strip by strip (a strip owns its voxels, each summed
// band after band). Within a band the x stages take a few dozen columns at a time, 16 rows at a
// time, so the pixels those columns share stay in L1. They work on the image in row lanes (each
// block of 16 rows stored column by column), so one x weight meets 16 rows in one vector
// operation; every pixel and voxel still gets its sums in the same order as row by row.
// docs/recon.md, "The kernels", has the layout and its reasons.
class ActiveSet {
 public:
  // `voxels`: flat indices into the operator's grid, strictly increasing (InputError otherwise).
  ActiveSet(const WeightingOperator& op, std::span<const std::uint32_t> voxels);
  static ActiveSet all(const WeightingOperator& op);
  ActiveSet();  // empty, for assign()
  ~ActiveSet();
  ActiveSet(ActiveSet&&) noexcept;
  ActiveSet& operator=(ActiveSet&&) noexcept;
  // Lays out another set in this one's storage (kept from set to set, so that a caller laying
  // out set after set neither allocates nor page-faults its large arrays again). The same
  // layout as a new ActiveSet(op, voxels). Takes the list from `voxels` and leaves there the
  // previous list's storage, emptied, for the caller to build the next list in: the two lists
  // trade places, and neither is allocated or faulted in again.
  void assign(const WeightingOperator& op, BigBuffer<std::uint32_t>& voxels);

  const BigBuffer<std::uint32_t>& voxels() const { return voxels_; }
  std::size_t size() const { return voxels_.size(); }
  // Where each depth slice's voxels lie in voxels() (the set is in index order, so each slice's
  // are one run): slice z's are [runs[z], runs[z + 1]), z = 0 .. the grid's depth.
  std::vector<std::size_t> slice_runs(const WeightingOperator& op) const;
  // The work of one pass, estimated as the kernels' vector operations: per visit, the x stage's
  // kQuad operations per x quad of its column on each block of kSubRows rows it reaches (a block
  // costs the same however few of its rows are reached), plus two per y quad of its voxels (the
  // y stage; the back-projection's runs in double).
  double pass_work() const { return pass_work_; }
  // Bytes held (the arrays' capacities, the construction's kept working arrays among them).
  std::size_t bytes() const;

  // Buffers a pass needs (E / n in column order, the back-projection's per-voxel sums, the images
  // in row lanes), kept by whoever runs many passes (MART) so that a pass neither allocates nor
  // page-faults them.
  struct Workspace {
    BigBuffer<float> scaled;
    // Per thread, the sums of the strip it back-projects (room for the largest strip's voxels).
    BigBuffer<double> sums;
    // The kernels' x stages take images in row lanes (blocks of 16 rows stored column by
    // column): one band per thread for a projection, the whole images for a back-projection.
    BigBuffer<float> band_lanes, image_lanes;
  };
  // Called once per band of sensor rows, pixels [first_pixel, end_pixel), as soon as a projection
  // has finished them, on the thread that computed them: per-pixel work on the projection while
  // the band is in cache. Bands are numbered 0..band_count() - 1 and cover the image in order.
  using BandDone = std::function<void(int band, std::size_t first_pixel, std::size_t end_pixel)>;
  // Sizes and writes `workspace` for this set's passes (a projection on as many threads as the
  // calling arena has, a back-projection), so that they neither grow nor page-fault it.
  void reserve(const WeightingOperator& op, Workspace& workspace) const;
  int band_count() const { return bands_; }

  // image = W·values (values per active voxel, image of the sensor's size, overwritten).
  void project(const WeightingOperator& op, std::span<const float> values, std::span<float> image,
               Workspace* workspace = nullptr, const BandDone& band_done = {}) const;
  // values = Wᵀ·image for the active voxels. The image must be finite: the 4-pixel quads also
  // read a few pixels beside a voxel's segments, with weight 0.
  void back_project(const WeightingOperator& op, std::span<const float> image, std::span<float> values) const;
  // The same for an image already multiplied pixel by pixel by the white correction (saves a
  // pass and a buffer inside MART's loop).
  void back_project_whitened(const WeightingOperator& op, std::span<const float> whitened_image,
                             std::span<float> values, Workspace* workspace = nullptr) const;

 private:
  // One voxel column (z, x) of the set: its voxels are order_[begin, end), y increasing.
  struct Column {
    int z = 0, x = 0;
    std::uint32_t begin = 0, end = 0;
  };
  // One voxel of a column in one band (its position in order_, its y quads over the band).
  using BandEntry = kernels::BandEntry;
  // Sensor rows per band. Few bands per voxel keep the per-band bookkeeping small; the pixels a
  // strip of voxel x reaches in one band stay in L2 (docs/recon.md, "Order and cache").
  static constexpr int kBandRows = 256;
  static constexpr int kRowWords = kBandRows / 64;
  // One column's share of one band, as the kernels visit it: its entries and, as bits, the band's
  // rows its voxels reach (the rows the two-stage kernels touch).
  struct Visit {                                // no initialisers, as BandEntry
    std::uint32_t column;                       // into columns_
    std::uint32_t entry_begin, entry_end;       // into entries_
    std::array<std::uint64_t, kRowWords> rows;  // bit r: row r0 + r of the band
  };
  // The construction's bookkeeping per column and band, and each voxel row's share of each band
  // (active_set.cpp).
  struct BandPlan;
  struct RowBands;
  // Those and the other working arrays of a construction, kept from set to set as the set's own
  // arrays are, so that laying out set after set (MART's pruning) does not fault them in again.
  struct Construction;

  // Visit `visit` as the y stages see it, its row sums at `sums` (passes.cpp).
  kernels::RowJob row_job(const WeightingOperator& op, std::size_t visit, float* sums) const;

  // The construction, step by step (active_set.cpp).
  void check_voxels(const WeightingOperator& op) const;
  // order_, order_normaliser_, columns_ and the strips; `order_y` gets each ordered voxel's y.
  void group_by_column(const WeightingOperator& op, BigBuffer<int>& order_y);
  // Per voxel row (z, y) of the grid: its y quads in each band and the band's rows they reach.
  static void row_bands(const WeightingOperator& op, RowBands& rows);
  // Which bands each column's voxels reach, and how many entries each (column, band) holds.
  void plan_bands(const WeightingOperator& op, const BigBuffer<int>& order_y, const RowBands& rows,
                  BandPlan& plan) const;
  // visit_start_ and visits_ (without their rows) in the kernels' reading order; `block_visit`
  // gets each (column, band) block's visit.
  void lay_out_visits(const BandPlan& plan, std::vector<std::size_t>& block_visit);
  // entries_ and each visit's reached rows.
  void fill_entries(const BigBuffer<int>& order_y, const RowBands& rows, BandPlan& plan,
                    const std::vector<std::size_t>& block_visit);
  // band_order_ and strip_order_: costliest first.
  void order_by_cost(const WeightingOperator& op);

  std::unique_ptr<Construction> construction_;
  BigBuffer<std::uint32_t> voxels_;
  // Voxels with a positive normaliser, in the kernels' visiting order (strip, depth, x, then y
  // increasing): position in voxels_ and n. A pass reads and writes its per-voxel arrays front to
  // back, and each strip owns one contiguous range of them.
  BigBuffer<std::uint32_t> order_;
  BigBuffer<float> order_normaliser_;
  std::vector<Column> columns_;  // in the same order
  // Voxel x per strip: within a band the kernels walk strip by strip, depth by depth, x by x, so
  // the y weights of one depth serve the whole strip and the pixels under the strip stay cached.
  double pass_work_ = 0;
  int strip_x_ = 1;
  int strips_ = 0;
  int bands_ = 0;
  std::vector<int> band_order_, strip_order_;  // the order passes hand them out: costliest first
  // strip s owns columns_[strip_columns_[s], strip_columns_[s + 1])
  std::vector<std::uint32_t> strip_columns_;
  // The voxels of the largest strip (the back-projection's per-thread sums).
  std::size_t largest_strip() const;
  // The visits of band b and strip s are visits_[visit_start_[b * strips_ + s],
  // visit_start_[b * strips_ + s + 1]); visits and their entries lie in the kernels' reading
  // order (band, strip, depth, x), so a pass streams through both.
  std::vector<std::size_t> visit_start_;
  BigBuffer<Visit> visits_;
  BigBuffer<BandEntry> entries_;
};

}  // namespace plenopiv::recon
