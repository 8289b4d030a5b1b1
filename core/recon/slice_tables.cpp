// The separable per-slice tables of the weighting operator (every voxel column's and row's 1-D
// weights, as segments and as the kernels' quads) and the eq 13 normalisers.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <vector>

#include "core/recon/kernels.hpp"
#include "core/recon/ray_geometry.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::recon {
namespace {

using kernels::kQuad;

// Away from focus a voxel reaches a few pixels behind each of many lenses: the tables keep only
// the stretches with weight, splitting where more than kGap pixels in a row have none (shorter
// gaps are cheaper to carry than to split).
constexpr int kGap = 2;
// A quad's padding reaches kQuad - 1 pixels past its segment, no further than the kGap + 1 or
// more empty pixels before the next segment.
static_assert(kGap + 1 >= kQuad - 1, "the quads of different segments must not overlap");

// The 1-D weights of `count` voxels along `axis` of a slice with optics `o`: for each voxel, the
// sum over the plaid aperture samples of every ray's coefficients (eq 11 times the pixel
// interpolation behind each lens), kept as segments of consecutive pixels with weight.
// `scratch` holds one double per pixel of the axis, all 0 (and left so).
template <typename PixelOf>
void build_axis_weights(const WeightingOperator::Geometry& geo, const Grid3& grid, const SliceOptics& o, int axis,
                        int count, const std::vector<double>& centres, int pixels, PixelOf pixel_of,
                        std::vector<double>& scratch, std::vector<WeightRun>& runs, std::vector<Segment>& segments,
                        std::vector<float>& table) {
  runs.resize(std::size_t(count));
  for (int v = 0; v < count; ++v) {
    const double prime = o.magnification * grid.coordinate_mm(axis, v);
    int lo = pixels, hi = -1;
    for (int k = 0; k < o.samples; ++k) {
      int pix[4];
      double w[4];
      const double u = detail::sample_position(geo.aperture, o.samples, k);
      const int n = detail::ray_coefficients(geo, centres, o.alpha, prime, u, pixels, pixel_of, pix, w);
      for (int h = 0; h < n; ++h) {
        scratch[std::size_t(pix[h])] += w[h];
        lo = std::min(lo, pix[h]);
        hi = std::max(hi, pix[h]);
      }
    }
    WeightRun& run = runs[std::size_t(v)];
    run.first = lo;
    run.last = hi;
    run.segment_begin = segments.size();
    for (int p = lo; p <= hi;) {
      if (scratch[std::size_t(p)] == 0.0) {
        ++p;
        continue;
      }
      int end = p;  // last pixel with weight in this stretch
      for (int q = p + 1; q <= hi && q <= end + kGap + 1; ++q) {
        if (scratch[std::size_t(q)] != 0.0) end = q;
      }
      segments.push_back(Segment{p, end - p + 1, table.size()});
      for (int q = p; q <= end; ++q) table.push_back(float(scratch[std::size_t(q)]));
      p = end + 1;
    }
    run.segment_end = segments.size();
    for (int p = lo; p <= hi; ++p) scratch[std::size_t(p)] = 0.0;
  }
}

// The kernels' form of one axis's weights: every segment cut into quads of kQuad pixels, voxel
// v owning quads [start[v], start[v + 1]). Along x a quad past the end of the row is shifted left
// and its lanes outside its own pixels weigh 0, so the kernels never touch a pixel outside the
// row (`shift_width`; 0 along y, whose quads weigh rows of the kernels' padded scratch arrays).
// The quads of different segments never overlap (kGap).
void build_quads(const std::vector<WeightRun>& runs, const std::vector<Segment>& segments,
                 const std::vector<float>& table, int shift_width, std::vector<std::size_t>& start,
                 std::vector<int>& quad_first, std::vector<float>& quad_weights) {
  start.assign(runs.size() + 1, 0);
  for (std::size_t v = 0; v < runs.size(); ++v) {
    const WeightRun& run = runs[v];
    for (std::size_t k = run.segment_begin; k < run.segment_end; ++k) {
      const Segment& s = segments[k];
      for (int c = 0; c < s.length; c += kQuad) {
        const int own_first = s.first + c, own_end = s.first + std::min(c + kQuad, s.length);
        const int first = shift_width > 0 ? std::min(own_first, shift_width - kQuad) : own_first;
        quad_first.push_back(first);
        for (int p = first; p < first + kQuad; ++p) {
          const bool own = p >= own_first && p < own_end;
          quad_weights.push_back(own ? table[s.offset + std::size_t(p - s.first)] : 0.f);
        }
      }
    }
    start[v + 1] = quad_first.size();
  }
}

}  // namespace

void WeightingOperator::build_slice_tables() {
  const int nx = grid_.shape[0], ny = grid_.shape[1], nz = grid_.shape[2];
  slices_.resize(std::size_t(nz));
  for (int z = 0; z < nz; ++z) slice_optics(grid_.coordinate_mm(2, z));  // validates every depth

  auto column_of = [this](double mm) { return optics::sensor_mm_to_column(sensor_, mm); };
  auto row_of = [this](double mm) { return optics::sensor_mm_to_row(sensor_, mm); };
  tbb::parallel_for(0, nz, [&](int z) {
    SliceTables& t = slices_[std::size_t(z)];
    t.z_mm = grid_.coordinate_mm(2, z);
    const SliceOptics o = slice_optics(t.z_mm);
    t.alpha = o.alpha;
    t.magnification = o.magnification;
    t.samples = o.samples;
    std::vector<double> scratch(std::size_t(std::max(width_, height_)), 0.0);
    build_axis_weights(geo_, grid_, o, 0, nx, geo_.lens_x, width_, column_of, scratch, t.x_runs, t.x_segments,
                       t.x_table);
    build_axis_weights(geo_, grid_, o, 1, ny, geo_.lens_y, height_, row_of, scratch, t.y_runs, t.y_segments, t.y_table);
    build_quads(t.x_runs, t.x_segments, t.x_table, width_, t.x_quad_start, t.x_quad_first, t.x_quad_weights);
    build_quads(t.y_runs, t.y_segments, t.y_table, 0, t.y_quad_start, t.y_quad_first, t.y_quad_weights);
  });
}

void WeightingOperator::compute_normalisers() {
  // Eq 13's denominators n_j = Σ_rows Ay Σ_cols Ax white, in two separable stages per slice.
  const int nx = grid_.shape[0], ny = grid_.shape[1], nz = grid_.shape[2];
  normaliser_.assign(grid_.count(), 0.f);
  tbb::parallel_for(0, nz, [&](int z) {
    const SliceTables& t = slices_[std::size_t(z)];
    int r_lo = height_, r_hi = -1;
    for (const WeightRun& r : t.y_runs) {
      if (r.last < r.first) continue;
      r_lo = std::min(r_lo, r.first);
      r_hi = std::max(r_hi, r.last);
    }
    if (r_hi < r_lo) return;
    const std::size_t rows = std::size_t(r_hi - r_lo + 1);
    std::vector<double> g(rows * std::size_t(nx), 0.0);  // [row][x]
    for (std::size_t r = 0; r < rows; r += 2) {
      const float* wrow = white_.pixels.data() + (std::size_t(r_lo) + r) * std::size_t(width_);
      kernels::dot_slice_rows(wrow, r + 1 < rows ? wrow + width_ : nullptr, t.x_quad_start.data(),
                              t.x_quad_first.data(), t.x_quad_weights.data(), nx, g.data() + r * std::size_t(nx),
                              g.data() + (r + 1) * std::size_t(nx));
    }
    for (int y = 0; y < ny; ++y) {
      const AxisWeights ay = y_weights(z, y);
      for (int x = 0; x < nx; ++x) {
        double s = 0;
        for (const Segment& seg : ay.segments) {
          for (int r = 0; r < seg.length; ++r) {
            s += double(ay.table[seg.offset + std::size_t(r)]) *
                 g[std::size_t(seg.first + r - r_lo) * std::size_t(nx) + std::size_t(x)];
          }
        }
        normaliser_[grid_.index(x, y, z)] = float(s);
      }
    }
  });
}

}  // namespace plenopiv::recon
