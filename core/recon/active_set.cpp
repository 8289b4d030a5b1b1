// Building an ActiveSet: the voxels grouped by column in the kernels' visiting order, then each
// column's share of each band of sensor rows (its visits, entries and reached rows), then the
// bands and strips ordered by cost for sharing out.
#include "core/recon/active_set.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <xmmintrin.h>

#include <algorithm>
#include <functional>
#include <limits>
#include <numeric>
#include <utility>

#include "core/base/errors.hpp"
#include "core/recon/kernels.hpp"

namespace plenopiv::recon {

using kernels::kQuad;

struct ActiveSet::BandPlan {
  // Per column: the first and last band its voxels' rows reach.
  std::vector<int> first_band, last_band;
  // Per (column c, band b) "block": block_offset[c] + b - first_band[c]; its entry count (counted
  // down again as fill_entries writes them).
  std::vector<std::size_t> block_offset;
  std::vector<std::uint32_t> block_entries;
};

struct ActiveSet::RowBands {
  // One voxel row's share of one band: its y quads that overlap the band (quad_count 0: none)
  // and, as a visit holds them, the band's rows they reach with a weight (bit j: row r0 + j).
  struct Share {
    std::uint32_t quad_begin, quad_count;
    std::array<std::uint64_t, kRowWords> rows;
  };
  // Voxel row (z, y) is zy = z ny + y: the first band its quads reach, and its shares of that band
  // and the next ones, shares[start[zy] .. start[zy + 1]).
  std::size_t ny = 0;
  std::vector<int> first_band;
  std::vector<std::size_t> start;
  BigBuffer<Share> shares;

  // Calls entry(b, share) for each band b in [first, last] in which voxel row zy has quads, in
  // band order: what walking the row's quads band by band gives, looked up.
  template <typename Entry>
  void walk(std::size_t zy, int first, int last, Entry&& entry) const {
    const int b0 = std::max(first, first_band[zy]);
    const int b1 = std::min(last, first_band[zy] + int(start[zy + 1] - start[zy]) - 1);
    for (int b = b0; b <= b1; ++b) {
      const Share& s = shares[start[zy] + std::size_t(b - first_band[zy])];
      if (s.quad_count) entry(b, s);
    }
  }
};

struct ActiveSet::Construction {
  BigBuffer<int> order_y;
  RowBands rows;
  BandPlan plan;
  std::vector<std::size_t> block_visit;
};

namespace {

// Calls entry(b, p, first quad, count) for each voxel p in [begin, end) of a column of slice `t`
// (y of voxel p: order_y[p]) whose y quads reach band b (a quad may reach two bands: it is in
// both), for bands [first_band, last_band] only: voxel by voxel in y order, each voxel's bands in
// order, so the entries of one band keep y order.
template <typename Entry>
void walk_column(const SliceTables& t, std::uint32_t begin, std::uint32_t end, const int* order_y, int first_band,
                 int last_band, int band_rows, int height, Entry&& entry) {
  for (std::uint32_t p = begin; p < end; ++p) {
    const std::size_t y = std::size_t(order_y[p]);
    const std::size_t q0 = t.y_quad_start[y], q1 = t.y_quad_start[y + 1];
    if (q0 == q1) continue;
    const int b0 = std::max(first_band, t.y_quad_first[q0] / band_rows);
    const int b1 = std::min(last_band, (t.y_quad_first[q1 - 1] + kQuad - 1) / band_rows);
    std::size_t k = q0;
    for (int b = b0; b <= b1; ++b) {
      const int r0 = b * band_rows, r1 = std::min(height, r0 + band_rows);
      while (k < q1 && t.y_quad_first[k] + kQuad <= r0) ++k;
      std::size_t e = k;
      while (e < q1 && t.y_quad_first[e] < r1) ++e;
      if (e > k) entry(b, p, k, e - k);
    }
  }
}

// Calls visit(c, b, p, share) for each voxel p of each column c and each band b of the column's
// range [plan.first_band[c], plan.last_band[c]] in which the voxel's row has quads: in parallel
// over columns, a column's calls in y order and each voxel's in band order.
template <typename Columns, typename Rows, typename Plan, typename Visit>
void for_each_share(const Columns& columns, const int* order_y, const Rows& rows, const Plan& plan, Visit&& visit) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, columns.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t c = range.begin(); c != range.end(); ++c) {
                        const auto& col = columns[c];
                        const std::size_t slice_rows = std::size_t(col.z) * rows.ny;
                        for (std::uint32_t p = col.begin; p < col.end; ++p)
                          rows.walk(slice_rows + std::size_t(order_y[p]), plan.first_band[c], plan.last_band[c],
                                    [&](int b, const auto& share) { visit(c, b, p, share); });
                      }
                    });
}

}  // namespace

ActiveSet::ActiveSet() = default;
ActiveSet::~ActiveSet() = default;
ActiveSet::ActiveSet(ActiveSet&&) noexcept = default;
ActiveSet& ActiveSet::operator=(ActiveSet&&) noexcept = default;

ActiveSet::ActiveSet(const WeightingOperator& op, std::span<const std::uint32_t> voxels) {
  BigBuffer<std::uint32_t> list(voxels.begin(), voxels.end());
  assign(op, list);
}

void ActiveSet::assign(const WeightingOperator& op, BigBuffer<std::uint32_t>& voxels) {
  voxels_.swap(voxels);
  voxels.clear();
  // Emptied, capacity kept: every step below sizes and writes what it uses.
  order_.clear();
  order_normaliser_.clear();
  columns_.clear();
  visits_.clear();
  entries_.clear();
  check_voxels(op);
  if (!construction_) construction_ = std::make_unique<Construction>();
  Construction& c = *construction_;
  group_by_column(op, c.order_y);
  bands_ = (op.image_height() + kBandRows - 1) / kBandRows;
  row_bands(op, c.rows);
  plan_bands(op, c.order_y, c.rows, c.plan);
  lay_out_visits(c.plan, c.block_visit);
  fill_entries(c.order_y, c.rows, c.plan, c.block_visit);
  order_by_cost(op);
}

ActiveSet ActiveSet::all(const WeightingOperator& op) {
  BigBuffer<std::uint32_t> v(op.grid().count());
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = std::uint32_t(i);
  ActiveSet set;
  set.assign(op, v);
  return set;
}

std::size_t ActiveSet::bytes() const {
  std::size_t construction = 0;
  if (construction_) {
    const Construction& c = *construction_;
    construction = c.order_y.capacity() * sizeof(int) + c.rows.first_band.capacity() * sizeof(int) +
                   c.rows.start.capacity() * sizeof(std::size_t) + c.rows.shares.capacity() * sizeof(RowBands::Share) +
                   (c.plan.first_band.capacity() + c.plan.last_band.capacity()) * sizeof(int) +
                   c.plan.block_offset.capacity() * sizeof(std::size_t) +
                   c.plan.block_entries.capacity() * sizeof(std::uint32_t) +
                   c.block_visit.capacity() * sizeof(std::size_t);
  }
  return voxels_.capacity() * sizeof(std::uint32_t) + order_.capacity() * sizeof(std::uint32_t) +
         order_normaliser_.capacity() * sizeof(float) + columns_.capacity() * sizeof(Column) +
         visits_.capacity() * sizeof(Visit) + entries_.capacity() * sizeof(BandEntry) +
         visit_start_.capacity() * sizeof(std::size_t) + construction;
}

std::vector<std::size_t> ActiveSet::slice_runs(const WeightingOperator& op) const {
  const Grid3& g = op.grid();
  const std::uint64_t slice = std::uint64_t(g.shape[0]) * std::uint64_t(g.shape[1]);
  std::vector<std::size_t> runs(std::size_t(g.shape[2]) + 1);
  for (std::size_t z = 0; z < runs.size(); ++z) {
    runs[z] = std::size_t(std::lower_bound(voxels_.begin(), voxels_.end(), z * slice) - voxels_.begin());
  }
  return runs;
}

void ActiveSet::check_voxels(const WeightingOperator& op) const {
  if (std::adjacent_find(voxels_.begin(), voxels_.end(), std::greater_equal<>()) != voxels_.end() ||
      (!voxels_.empty() && voxels_.back() >= op.grid().count())) {
    throw InputError("active set: voxel indices must be distinct, increasing and inside the grid");
  }
}

void ActiveSet::group_by_column(const WeightingOperator& op, BigBuffer<int>& order_y) {
  const Grid3& g = op.grid();
  const std::uint32_t nx = std::uint32_t(g.shape[0]), nz = std::uint32_t(g.shape[2]);
  const std::uint32_t nxy = nx * std::uint32_t(g.shape[1]);
  // 16 voxel x per strip, fewer on small grids so that there are at least 8 strips to share
  // out; fixed by the grid, so the sums' order is too.
  strip_x_ = std::clamp(int(nx) / 8, 1, 16);
  strips_ = (int(nx) + strip_x_ - 1) / strip_x_;
  const std::uint32_t sx = std::uint32_t(strip_x_);
  // A voxel column's place in the visiting order: strip, depth, x within the strip.
  auto key_of = [&](std::uint32_t x, std::uint32_t z) { return (std::size_t(x / sx) * nz + z) * sx + x % sx; };
  // Group by voxel column in that order with a counting sort, slice by slice in parallel (the
  // voxels are sorted, so each slice is one stretch of them): y stays increasing within a
  // column. A voxel that sees no pixel (n = 0) takes no part; its value is 0.
  const std::vector<std::size_t> slice_begin = slice_runs(op);
  std::vector<std::uint32_t> column_count(std::size_t(nz) * nx, 0);  // [z][x]
  tbb::parallel_for(std::uint32_t(0), nz, [&](std::uint32_t z) {
    for (std::size_t m = slice_begin[z]; m < slice_begin[z + 1]; ++m) {
      if (op.normaliser(voxels_[m]) > 0.f) ++column_count[std::size_t(z) * nx + voxels_[m] % nx];
    }
  });
  std::vector<std::uint32_t> start(std::size_t(strips_) * nz * sx + 1, 0);
  for (std::uint32_t z = 0; z < nz; ++z) {
    for (std::uint32_t x = 0; x < nx; ++x) {
      start[key_of(x, z) + 1] = column_count[std::size_t(z) * nx + x];
    }
  }
  for (std::size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
  order_.resize(start.back());
  order_normaliser_.resize(start.back());
  order_y.resize(start.back());  // written in full below
  tbb::parallel_for(std::uint32_t(0), nz, [&](std::uint32_t z) {
    // Now each column's next place.
    std::uint32_t* fill = column_count.data() + std::size_t(z) * nx;
    for (std::uint32_t x = 0; x < nx; ++x) fill[x] = start[key_of(x, z)];
    for (std::size_t m = slice_begin[z]; m < slice_begin[z + 1]; ++m) {
      const std::uint32_t v = voxels_[m];
      const float n = op.normaliser(v);
      if (!(n > 0.f)) continue;
      const std::uint32_t p = fill[v % nx]++;
      order_[p] = std::uint32_t(m);
      order_y[p] = int((v % nxy) / nx);
      order_normaliser_[p] = n;
    }
  });
  strip_columns_.assign(std::size_t(strips_) + 1, 0);
  for (std::size_t key = 0; key + 1 < start.size(); ++key) {
    if (start[key + 1] == start[key]) continue;
    const std::size_t strip = key / (std::size_t(nz) * sx);
    columns_.push_back(Column{int((key / sx) % nz), int(strip * sx + key % sx), start[key], start[key + 1]});
    strip_columns_[strip + 1] = std::uint32_t(columns_.size());
  }
  for (std::size_t s = 1; s <= std::size_t(strips_); ++s) {
    strip_columns_[s] = std::max(strip_columns_[s], strip_columns_[s - 1]);
  }
}

void ActiveSet::plan_bands(const WeightingOperator& op, const BigBuffer<int>& order_y, const RowBands& rows,
                           BandPlan& plan) const {
  const int height = op.image_height();
  plan.first_band.resize(columns_.size());
  plan.last_band.resize(columns_.size());
  // Entries per (column, band), counted in parallel over columns.
  plan.block_offset.assign(columns_.size() + 1, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, columns_.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t c = range.begin(); c != range.end(); ++c) {
                        const Column& col = columns_[c];
                        const SliceTables& t = op.slice(col.z);
                        plan.first_band[c] = height;
                        plan.last_band[c] = -1;
                        for (std::uint32_t p = col.begin; p < col.end; ++p) {
                          const WeightRun& run = t.y_runs[std::size_t(order_y[p])];
                          plan.first_band[c] = std::min(plan.first_band[c], run.first / kBandRows);
                          plan.last_band[c] = std::max(plan.last_band[c], run.last / kBandRows);
                        }
                        plan.block_offset[c + 1] = std::size_t(plan.last_band[c] - plan.first_band[c] + 1);
                      }
                    });
  for (std::size_t c = 0; c < columns_.size(); ++c) plan.block_offset[c + 1] += plan.block_offset[c];
  plan.block_entries.assign(plan.block_offset.back(), 0);
  for_each_share(columns_, order_y.data(), rows, plan,
                 [&](std::size_t c, int b, std::uint32_t, const RowBands::Share&) {
                   ++plan.block_entries[plan.block_offset[c] + std::size_t(b - plan.first_band[c])];
                 });
}

void ActiveSet::lay_out_visits(const BandPlan& plan, std::vector<std::size_t>& block_visit) {
  // The visits in the order the kernels read them: band by band, then strip by strip, depth by
  // depth, x by x (columns_'s order), each with its entries; counted, then laid out.
  auto for_each_visit = [&](auto&& f) {
    for (int b = 0; b < bands_; ++b) {
      for (int s = 0; s < strips_; ++s) {
        for (std::uint32_t c = strip_columns_[std::size_t(s)]; c < strip_columns_[std::size_t(s) + 1]; ++c) {
          if (b < plan.first_band[c] || b > plan.last_band[c]) continue;
          const std::size_t block = plan.block_offset[c] + std::size_t(b - plan.first_band[c]);
          if (plan.block_entries[block] > 0) f(b, s, c, block);
        }
      }
    }
  };
  visit_start_.assign(std::size_t(bands_) * std::size_t(strips_) + 1, 0);
  for_each_visit([&](int b, int s, std::uint32_t, std::size_t) {
    ++visit_start_[std::size_t(b) * std::size_t(strips_) + std::size_t(s) + 1];
  });
  for (std::size_t i = 1; i < visit_start_.size(); ++i) visit_start_[i] += visit_start_[i - 1];
  visits_.resize(visit_start_.back());
  block_visit.resize(plan.block_offset.back());  // every block with entries written below
  std::size_t next_visit = 0, next_entry = 0;
  for_each_visit([&](int, int, std::uint32_t c, std::size_t block) {
    if (next_entry + plan.block_entries[block] > std::numeric_limits<std::uint32_t>::max()) {
      throw InputError("reconstruction: more than 2^32 voxel-band entries; use a coarser volume grid");
    }
    Visit& v = visits_[next_visit];
    v.column = c;
    v.entry_begin = std::uint32_t(next_entry);
    next_entry += plan.block_entries[block];
    v.entry_end = std::uint32_t(next_entry);
    v.rows = {};
    block_visit[block] = next_visit++;
  });
  entries_.resize(next_entry);
}

void ActiveSet::row_bands(const WeightingOperator& op, RowBands& rows) {
  const int height = op.image_height();
  const std::size_t ny = std::size_t(op.grid().shape[1]), nz = std::size_t(op.grid().shape[2]);
  rows.ny = ny;
  rows.first_band.assign(nz * ny, 0);
  rows.start.assign(nz * ny + 1, 0);
  for (std::size_t z = 0; z < nz; ++z) {
    const SliceTables& t = op.slice(int(z));
    // What a BandEntry can address (kernels.hpp); far beyond any camera's grid.
    if (t.y_quad_start[ny] >= kernels::kMaxSliceQuads)
      throw InputError("reconstruction grid: depth slice " + std::to_string(z) + " reaches " +
                       std::to_string(t.y_quad_start[ny]) + " y quads on the sensor, more than the " +
                       std::to_string(kernels::kMaxSliceQuads - 1) + " a slice can hold: use fewer voxels along y");
    for (std::size_t y = 0; y < ny; ++y) {
      const std::size_t q0 = t.y_quad_start[y], q1 = t.y_quad_start[y + 1], zy = z * ny + y;
      if (q1 - q0 > kernels::kMaxEntryQuads)
        throw InputError("reconstruction grid: voxel row y " + std::to_string(y) + " of depth slice " +
                         std::to_string(z) + " reaches " + std::to_string(q1 - q0) +
                         " y quads on the sensor, more than the " + std::to_string(kernels::kMaxEntryQuads) +
                         " a voxel can hold");
      std::size_t bands = 0;
      if (q0 < q1) {
        rows.first_band[zy] = t.y_quad_first[q0] / kBandRows;
        bands = std::size_t((t.y_quad_first[q1 - 1] + kQuad - 1) / kBandRows - rows.first_band[zy] + 1);
      }
      rows.start[zy + 1] = rows.start[zy] + bands;
    }
  }
  // Each share written in full (BigBuffer does not zero): the bands a row's quads skip keep
  // quad_count 0.
  rows.shares.resize(rows.start.back());
  tbb::parallel_for(std::size_t(0), nz, [&](std::size_t z) {
    const SliceTables& t = op.slice(int(z));
    for (std::size_t y = 0; y < ny; ++y) {
      const std::size_t zy = z * ny + y;
      for (std::size_t i = rows.start[zy]; i < rows.start[zy + 1]; ++i) rows.shares[i] = RowBands::Share{0, 0, {}};
      const int order_of_y = int(y);
      walk_column(t, 0, 1, &order_of_y, rows.first_band[zy], std::numeric_limits<int>::max(), kBandRows, height,
                  [&](int b, std::uint32_t, std::size_t k, std::size_t n) {
                    RowBands::Share& share = rows.shares[rows.start[zy] + std::size_t(b - rows.first_band[zy])];
                    share.quad_begin = std::uint32_t(k);
                    share.quad_count = std::uint32_t(n);
                    const int r0 = b * kBandRows, r1 = std::min(height, r0 + kBandRows);
                    // The rows with weight, a quad's lanes at a time: bit j for row first + j,
                    // without the lanes in the neighbouring bands.
                    for (std::size_t q = k; q < k + n; ++q) {
                      const float* w = t.y_quad_weights.data() + kQuad * q;
                      // Bit j: lane j's weight is not 0 (one SSE compare, not four scalar ones).
                      std::uint64_t lanes =
                          std::uint64_t(_mm_movemask_ps(_mm_cmpneq_ps(_mm_loadu_ps(w), _mm_setzero_ps())));
                      int at = t.y_quad_first[q] - r0;
                      if (at < 0) {
                        lanes >>= -at;
                        at = 0;
                      }
                      if (r1 - r0 - at < kQuad) lanes &= (std::uint64_t(1) << (r1 - r0 - at)) - 1;
                      share.rows[std::size_t(at >> 6)] |= lanes << (at & 63);
                      if ((at & 63) > 64 - kQuad && (at >> 6) + 1 < kRowWords) {
                        share.rows[std::size_t(at >> 6) + 1] |= lanes >> (64 - (at & 63));
                      }
                    }
                  });
    }
  });
}

void ActiveSet::fill_entries(const BigBuffer<int>& order_y, const RowBands& rows, BandPlan& plan,
                             const std::vector<std::size_t>& block_visit) {
  // Each voxel's shares of its column's bands come from its row's (the same for every voxel column
  // x); a visit's rows are the OR of its entries' (in any order: the same bits).
  for_each_share(columns_, order_y.data(), rows, plan,
                 [&](std::size_t c, int b, std::uint32_t p, const RowBands::Share& share) {
                   const std::size_t block = plan.block_offset[c] + std::size_t(b - plan.first_band[c]);
                   Visit& v = visits_[block_visit[block]];
                   // In y order.
                   BandEntry& e = entries_[v.entry_end - plan.block_entries[block]--];
                   e.position = p;
                   e.quad_begin = share.quad_begin;
                   e.quad_count = share.quad_count;
                   for (int word = 0; word < kRowWords; ++word)
                     v.rows[std::size_t(word)] |= share.rows[std::size_t(word)];
                 });
}

void ActiveSet::order_by_cost(const WeightingOperator& op) {
  // The work of each band and strip, estimated as the kernels' vector operations (pass_work()):
  // each (band, strip) slot's visits in parallel, then the slots into bands and strips. Every cost
  // is a whole number far below 2^53, so the double sums are exact in any order.
  const std::size_t slots = std::size_t(bands_) * std::size_t(strips_);
  std::vector<double> slot_cost(slots, 0.0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, slots), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t slot = range.begin(); slot != range.end(); ++slot) {
      double sum = 0;
      for (std::size_t i = visit_start_[slot]; i < visit_start_[slot + 1]; ++i) {
        const Visit& v = visits_[i];
        const Column& col = columns_[v.column];
        const SliceTables& t = op.slice(col.z);
        // The x stages take a block of kSubRows rows whole if the visit reaches any of its rows.
        int blocks = 0;
        for (std::uint64_t word : v.rows) {
          for (int sub = 0; sub < 64; sub += kernels::kSubRows) blocks += ((word >> sub) & kernels::kSubMask) != 0;
        }
        const std::size_t x_quads = t.x_quad_start[std::size_t(col.x) + 1] - t.x_quad_start[std::size_t(col.x)];
        std::size_t y_quads = 0;
        for (std::size_t k = v.entry_begin; k < v.entry_end; ++k) y_quads += entries_[k].quad_count;
        sum += double(kQuad) * double(blocks) * double(x_quads) + 2.0 * double(y_quads);
      }
      slot_cost[slot] = sum;
    }
  });
  std::vector<double> band_cost(std::size_t(bands_), 0.0), strip_cost(std::size_t(strips_), 0.0);
  for (int b = 0; b < bands_; ++b) {
    for (int s = 0; s < strips_; ++s) {
      const double cost = slot_cost[std::size_t(b) * std::size_t(strips_) + std::size_t(s)];
      band_cost[std::size_t(b)] += cost;
      strip_cost[std::size_t(s)] += cost;
    }
  }
  auto costliest_first = [](const std::vector<double>& cost) {
    std::vector<int> order(cost.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int b) { return cost[std::size_t(a)] > cost[std::size_t(b)]; });
    return order;
  };
  pass_work_ = std::accumulate(band_cost.begin(), band_cost.end(), 0.0);
  band_order_ = costliest_first(band_cost);
  strip_order_ = costliest_first(strip_cost);
}

}  // namespace plenopiv::recon
