// The explicit weighting matrix of sec 5.2, built literally ray by ray (the small-case reference).
#include "core/recon/explicit_matrix.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <utility>

#include "core/recon/ray_geometry.hpp"

namespace plenopiv::recon {

void SparseMatrix::multiply(std::span<const float> x, std::span<float> y) const {
  for (std::size_t r = 0; r < rows; ++r) {
    double s = 0;
    for (std::size_t k = row_start[r]; k < row_start[r + 1]; ++k) s += double(values[k]) * x[col_index[k]];
    y[r] = float(s);
  }
}

void SparseMatrix::multiply_transpose(std::span<const float> y, std::span<float> x) const {
  std::vector<double> acc(cols, 0.0);
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t k = row_start[r]; k < row_start[r + 1]; ++k) acc[col_index[k]] += double(values[k]) * y[r];
  }
  for (std::size_t c = 0; c < cols; ++c) x[c] = float(acc[c]);
}

SparseMatrix build_explicit_matrix(const WeightingOperator& op) {
  const Grid3& g = op.grid();
  const WeightingOperator::Geometry& geo = op.geometry();
  const int width = op.image_width(), height = op.image_height();
  const optics::SensorSpec& sensor = op.sensor();
  auto column_of = [&](double mm) { return optics::sensor_mm_to_column(sensor, mm); };
  auto row_of = [&](double mm) { return optics::sensor_mm_to_row(sensor, mm); };

  // Columns of W (one per voxel), each a list of (pixel, weight).
  std::vector<std::vector<std::pair<std::uint32_t, float>>> columns(g.count());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, g.count(), 16), [&](const tbb::blocked_range<std::size_t>& range) {
        std::vector<std::pair<std::uint32_t, double>> entries;
        for (std::size_t j = range.begin(); j != range.end(); ++j) {
          const int x = int(j % std::size_t(g.shape[0]));
          const int y = int((j / std::size_t(g.shape[0])) % std::size_t(g.shape[1]));
          const int z = int(j / (std::size_t(g.shape[0]) * std::size_t(g.shape[1])));
          const SliceOptics o = op.slice_optics(g.coordinate_mm(2, z));
          const double xp = o.magnification * g.coordinate_mm(0, x);
          const double yp = o.magnification * g.coordinate_mm(1, y);
          entries.clear();
          // Literally sec 5.2: every ray of the plaid (u, v) grid through the voxel, its 4 lenses
          // and 4 pixels behind each (eq 12), times the white image (fig 15).
          for (int ku = 0; ku < o.samples; ++ku) {
            const double u = detail::sample_position(geo.aperture, o.samples, ku);
            int cu[4];
            double wu[4];
            const int nu = detail::ray_coefficients(geo, geo.lens_x, o.alpha, xp, u, width, column_of, cu, wu);
            for (int kv = 0; kv < o.samples; ++kv) {
              const double v = detail::sample_position(geo.aperture, o.samples, kv);
              int rv[4];
              double wv[4];
              const int nv = detail::ray_coefficients(geo, geo.lens_y, o.alpha, yp, v, height, row_of, rv, wv);
              for (int a = 0; a < nu; ++a) {
                for (int b = 0; b < nv; ++b) {
                  const std::uint32_t pixel = std::uint32_t(rv[b]) * std::uint32_t(width) + std::uint32_t(cu[a]);
                  const double w = wu[a] * wv[b] * op.white().pixels[pixel];
                  if (w > 0) entries.emplace_back(pixel, w);
                }
              }
            }
          }
          std::sort(entries.begin(), entries.end(), [](const auto& p, const auto& q) { return p.first < q.first; });
          double total = 0;
          for (const auto& e : entries) total += e.second;
          auto& col = columns[j];
          for (std::size_t k = 0; k < entries.size();) {
            double s = 0;
            const std::uint32_t pixel = entries[k].first;
            for (; k < entries.size() && entries[k].first == pixel; ++k) s += entries[k].second;
            col.emplace_back(pixel, float(s / total));  // eq 13
          }
        }
      });

  SparseMatrix m;
  m.rows = op.pixel_count();
  m.cols = g.count();
  m.row_start.assign(m.rows + 1, 0);
  for (const auto& col : columns) {
    for (const auto& e : col) ++m.row_start[e.first + 1];
  }
  for (std::size_t r = 0; r < m.rows; ++r) m.row_start[r + 1] += m.row_start[r];
  m.col_index.resize(m.row_start.back());
  m.values.resize(m.row_start.back());
  std::vector<std::size_t> fill(m.row_start.begin(), m.row_start.end() - 1);
  for (std::size_t j = 0; j < columns.size(); ++j) {
    for (const auto& e : columns[j]) {
      const std::size_t k = fill[e.first]++;
      m.col_index[k] = std::uint32_t(j);
      m.values[k] = e.second;
    }
  }
  return m;
}

}  // namespace plenopiv::recon
