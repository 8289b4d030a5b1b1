// The matrix-free passes over an ActiveSet: projection W·E band by band and back-projection
// Wᵀ·r strip by strip, each in a fixed order of sums whatever the thread count.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <vector>

#include "core/recon/active_set.hpp"
#include "core/recon/kernels.hpp"

namespace plenopiv::recon {

using kernels::ColumnJob;
using kernels::kChunk;
using kernels::kQuad;
using kernels::x_job;

namespace {

// Runs f(item) for every item on the arena's threads, each thread taking the next item of the
// list when it is free. With the costliest items first, a pass ends on short ones instead of
// leaving a core idle while the other finishes a long last band or strip. Which thread runs an
// item does not change any sum.
template <typename F>
void run_costliest_first(const std::vector<int>& items, F&& f) {
  std::atomic<std::size_t> next{0};
  const int workers = std::max(1, std::min(tbb::this_task_arena::max_concurrency(), int(items.size())));
  tbb::parallel_for(
      0, workers,
      [&](int) {
        for (std::size_t i = next++; i < items.size(); i = next++) f(items[i]);
      },
      tbb::simple_partitioner());
}

}  // namespace

kernels::RowJob ActiveSet::row_job(const WeightingOperator& op, std::size_t visit, float* sums) const {
  const Visit& v = visits_[visit];
  const SliceTables& t = op.slice(columns_[v.column].z);
  return kernels::RowJob{sums, entries_.data() + v.entry_begin, std::size_t(v.entry_end - v.entry_begin),
                         t.y_quad_first.data(), t.y_quad_weights.data()};
}

std::size_t ActiveSet::largest_strip() const {
  std::size_t largest = 0;
  for (int s = 0; s < strips_; ++s) {
    const std::uint32_t c0 = strip_columns_[std::size_t(s)], c1 = strip_columns_[std::size_t(s) + 1];
    if (c0 < c1) largest = std::max<std::size_t>(largest, columns_[c1 - 1].end - columns_[c0].begin);
  }
  return largest;
}

void ActiveSet::reserve(const WeightingOperator& op, Workspace& workspace) const {
  // The sizes project and back_project_whitened give these buffers.
  const std::size_t band_size = std::size_t(kBandRows) * std::size_t(op.image_width());
  workspace.scaled.assign(order_.size(), 0.f);
  workspace.sums.assign(std::size_t(tbb::this_task_arena::max_concurrency()) * largest_strip(), 0.0);
  workspace.band_lanes.assign(std::size_t(tbb::this_task_arena::max_concurrency()) * band_size, 0.f);
  workspace.image_lanes.assign(std::size_t(bands_) * band_size, 0.f);
}

void ActiveSet::project(const WeightingOperator& op, std::span<const float> values, std::span<float> image,
                        Workspace* workspace, const BandDone& band_done) const {
  const std::size_t width = std::size_t(op.image_width());
  const int height = op.image_height();
  Workspace local;
  Workspace& ws = workspace ? *workspace : local;
  // E / n once per voxel, in visiting order.
  auto& scaled = ws.scaled;
  scaled.resize(order_.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, order_.size(), 1 << 14),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t p = r.begin(); p != r.end(); ++p)
                        scaled[p] = values[order_[p]] / order_normaliser_[p];
                    });
  const std::size_t band_size = std::size_t(kBandRows) * width;
  ws.band_lanes.resize(std::size_t(tbb::this_task_arena::max_concurrency()) * band_size);
  // Each band owns its sensor rows and adds its columns in a fixed order: no atomics, and the
  // same sums whatever the thread count.
  run_costliest_first(band_order_, [&](int b) {
    const int r0 = b * kBandRows, r1 = std::min(height, r0 + kBandRows);
    // The band in row lanes, this thread's own, copied into the image when finished.
    float* lanes = ws.band_lanes.data() + std::size_t(tbb::this_task_arena::current_thread_index()) * band_size;
    std::fill_n(lanes, band_size, 0.f);
    // G(row) of kChunk consecutive visits over the band's rows, each with kQuad rows of margin on
    // either side for the lanes of quads that straddle the band's edges (those belong to the
    // neighbouring band). Zero between uses: stage 2 resets the rows it adds, then the margins.
    std::array<std::array<float, kQuad + kBandRows + kQuad>, kChunk> padded_sums;
    for (auto& p : padded_sums) p.fill(0.f);
    const std::size_t v_begin = visit_start_[std::size_t(b) * std::size_t(strips_)];
    const std::size_t v_end = visit_start_[std::size_t(b + 1) * std::size_t(strips_)];
    for (std::size_t c0 = v_begin; c0 < v_end; c0 += kChunk) {
      const std::size_t c1 = std::min(v_end, c0 + kChunk);
      // Stage 1: G(row) = Σ_y Ay_y(row) E_y / n_y over each visit's voxels that reach the band.
      std::array<kernels::RowJob, kChunk> row_jobs;
      for (std::size_t v = c0; v < c1; ++v) row_jobs[v - c0] = row_job(op, v, padded_sums[v - c0].data() + kQuad);
      kernels::add_rows(row_jobs.data(), int(c1 - c0), r0, scaled.data());
      // Stage 2: lanes(row, ·) += G(row) Ax over each 16-row block the column reaches (resets
      // G there), one block at a time for all the chunk's visits, so the pixels they share stay
      // in L1. Every pixel still gets its visits' additions in visiting order.
      std::array<ColumnJob, kChunk> jobs;
      for (std::size_t v = c0; v < c1; ++v) {
        const Column& col = columns_[visits_[v].column];
        jobs[v - c0] = x_job(op.slice(col.z), col.x, visits_[v].rows.data());
        jobs[v - c0].sums = padded_sums[v - c0].data() + kQuad;
      }
      kernels::add_columns(lanes, width, kRowWords, jobs.data(), int(c1 - c0));
      for (std::size_t v = c0; v < c1; ++v) {
        std::fill_n(padded_sums[v - c0].begin(), kQuad, 0.f);
        std::fill_n(padded_sums[v - c0].end() - kQuad, kQuad, 0.f);
      }
    }
    kernels::lanes_to_rows(lanes, width, r1 - r0, image.data() + std::size_t(r0) * width);
    const float* white = op.white().pixels.data();
    kernels::white_band(image.data() + std::size_t(r0) * width, white + std::size_t(r0) * width,
                        std::size_t(r1 - r0) * width);
    if (band_done) band_done(b, std::size_t(r0) * width, std::size_t(r1) * width);
  });
}

void ActiveSet::back_project(const WeightingOperator& op, std::span<const float> image, std::span<float> values) const {
  std::vector<float> whitened(image.size());
  const float* white = op.white().pixels.data();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, image.size(), 1 << 14),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) whitened[i] = image[i] * white[i];
                    });
  back_project_whitened(op, whitened, values);
}

void ActiveSet::back_project_whitened(const WeightingOperator& op, std::span<const float> image,
                                      std::span<float> values, Workspace* workspace_or_null) const {
  Workspace local;
  Workspace& workspace = workspace_or_null ? *workspace_or_null : local;
  const std::size_t width = std::size_t(op.image_width());
  std::fill_n(values.begin(), voxels_.size(), 0.f);  // voxels that see no pixel
  // Per voxel of a strip in visiting order, in the slot of the thread that back-projects it.
  const std::size_t strip_room = largest_strip();
  auto& sums = workspace.sums;
  sums.resize(std::size_t(tbb::this_task_arena::max_concurrency()) * strip_room);
  // The image in row lanes, band by band in parallel: the last block's rows past the sensor are
  // 0; blocks wholly past it are left unwritten (no visit reaches them, so none is read).
  const int height = op.image_height();
  workspace.image_lanes.resize(std::size_t(bands_) * std::size_t(kBandRows) * width);
  tbb::parallel_for(0, bands_, [&](int band) {
    const int r0 = band * kBandRows;
    kernels::rows_to_lanes(image.data() + std::size_t(r0) * width, width, std::min(height, r0 + kBandRows) - r0,
                           workspace.image_lanes.data() + std::size_t(r0) * width);
  });
  // Each strip owns its voxels (a contiguous range of order_), so their sums need no atomics,
  // and every voxel adds its bands in order whatever the thread count.
  run_costliest_first(strip_order_, [&](int strip) {
    const std::uint32_t c0 = strip_columns_[std::size_t(strip)], c1 = strip_columns_[std::size_t(strip) + 1];
    if (c0 == c1) return;
    const std::uint32_t p0 = columns_[c0].begin, p1 = columns_[c1 - 1].end;
    double* strip_sums = sums.data() + std::size_t(tbb::this_task_arena::current_thread_index()) * strip_room;
    std::fill_n(strip_sums, p1 - p0, 0.0);
    // B(row) of kChunk consecutive visits over the band's rows, with kQuad rows of margin on
    // either side, all 0 except the rows the column reaches: the lanes of y quads outside the
    // band, and their zero lanes on rows the column does not reach, then add 0 · 0 (a stale
    // value from another column would give 0 too if finite, but not if a row sum overflowed).
    std::array<std::array<float, kQuad + kBandRows + kQuad>, kChunk> padded_sums;
    for (int b = 0; b < bands_; ++b) {
      const int r0 = b * kBandRows;
      const std::size_t slot = std::size_t(b) * std::size_t(strips_) + std::size_t(strip);
      for (std::size_t v0 = visit_start_[slot]; v0 < visit_start_[slot + 1]; v0 += kChunk) {
        const std::size_t v1 = std::min(visit_start_[slot + 1], v0 + kChunk);
        for (std::size_t v = v0; v < v1; ++v) padded_sums[v - v0].fill(0.f);
        // Stage 1: B(row) = Σ_col Ax(col) r(row, col) over each 16-row block the column reaches
        // (its unreached rows kept 0), one block at a time for all the chunk's visits, so the
        // pixels they share stay in L1.
        std::array<ColumnJob, kChunk> jobs;
        for (std::size_t v = v0; v < v1; ++v) {
          const Column& col = columns_[visits_[v].column];
          jobs[v - v0] = x_job(op.slice(col.z), col.x, visits_[v].rows.data());
          jobs[v - v0].sums = padded_sums[v - v0].data() + kQuad;
        }
        kernels::dot_columns(workspace.image_lanes.data() + std::size_t(r0) * width, width, kRowWords, jobs.data(),
                             int(v1 - v0));
        // Stage 2: per voxel Σ_row Ay(row) B(row) over the band's rows.
        std::array<kernels::RowJob, kChunk> row_jobs;
        for (std::size_t v = v0; v < v1; ++v) row_jobs[v - v0] = row_job(op, v, padded_sums[v - v0].data() + kQuad);
        kernels::dot_rows(row_jobs.data(), int(v1 - v0), r0, strip_sums, p0);
      }
    }
    for (std::uint32_t p = p0; p < p1; ++p)
      values[order_[p]] = float(strip_sums[p - p0] / order_normaliser_[p]);  // eq 13
  });
}

}  // namespace plenopiv::recon
