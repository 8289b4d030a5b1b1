// The voxels a reconstruction solves: dark pixels as bits per sensor column, the separable
// "seen by a dark pixel" test per voxel, the region and the field of view.
#include "core/recon/voxel_selection.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>

#include "core/recon/mart_numerics.hpp"

namespace plenopiv::recon::detail {

void threshold_image(const ImageF& image, float threshold, BigBuffer<float>& out) {
  fit(out, image.pixels.size());
  for_pixels(out.size(), [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) out[i] = image.pixels[i] > threshold ? image.pixels[i] : 0.f;
  });
}

bool in_region(const Grid3& g, const std::optional<RegionMm>& region, int x, int y, int z) {
  if (!region) return true;
  const int idx[3] = {x, y, z};
  for (int a = 0; a < 3; ++a) {
    const double c = g.coordinate_mm(a, idx[a]);
    if (c < region->min_mm[a] || c > region->max_mm[a]) return false;
  }
  return true;
}

void select_active(const WeightingOperator& op, std::span<const float> image, const MartSettings& settings,
                   SelectScratch& scratch, SkipReport& report, BigBuffer<std::uint32_t>& active) {
  const Grid3& g = op.grid();
  const int width = op.image_width(), height = op.image_height();
  const std::size_t words = std::size_t(height + 63) / 64;  // per sensor column
  std::vector<std::uint64_t>& dark = scratch.dark;          // [column][row word]
  dark.assign(std::size_t(width) * words, 0);
  const float* white = op.white().pixels.data();
  report.pixels = op.pixel_count();
  // Each group of 64 sensor rows owns its word of every column.
  std::vector<std::size_t> dark_in_group(words, 0);
  tbb::parallel_for(std::size_t(0), words, [&](std::size_t w) {
    std::size_t count = 0;
    const int r1 = std::min(height, int(64 * w) + 64);
    for (int r = int(64 * w); r < r1; ++r) {
      const std::uint64_t bit = std::uint64_t(1) << (r & 63);
      const std::size_t row = std::size_t(r) * std::size_t(width);
      for (int c = 0; c < width; ++c) {
        if (white[row + std::size_t(c)] > 0.f && image[row + std::size_t(c)] == 0.f) {
          dark[std::size_t(c) * words + w] |= bit;
          ++count;
        }
      }
    }
    dark_in_group[w] = count;
  });
  for (std::size_t count : dark_in_group) report.dark_pixels += count;

  const int nx = g.shape[0], ny = g.shape[1], nz = g.shape[2];
  const float cutoff = float(settings.dark_weight_cutoff);
  report.voxels = g.count();
  report.slices = nz;
  std::vector<std::vector<std::uint32_t>>& per_slice = scratch.per_slice;
  per_slice.resize(std::size_t(nz));
  std::vector<std::array<std::size_t, 3>> counts(std::size_t(nz), {0, 0, 0});  // unseen, outside, dark
  auto peak_of = [](const AxisWeights& a) {
    float peak = 0.f;
    for (const Segment& s : a.segments) {
      for (int k = 0; k < s.length; ++k) peak = std::max(peak, a.table[s.offset + std::size_t(k)]);
    }
    return peak;
  };
  tbb::parallel_for(0, nz, [&](int z) {
    // Per voxel column x: the sensor rows where one of its strong columns is dark.
    std::vector<std::uint64_t> dark_rows(std::size_t(nx) * words, 0);
    for (int x = 0; x < nx; ++x) {
      const AxisWeights ax = op.x_weights(z, x);
      const float cut = cutoff * peak_of(ax);
      std::uint64_t* rows = dark_rows.data() + std::size_t(x) * words;
      for (const Segment& s : ax.segments) {
        for (int c = 0; c < s.length; ++c) {
          if (!(ax.table[s.offset + std::size_t(c)] > cut)) continue;
          const std::uint64_t* column = dark.data() + std::size_t(s.first + c) * words;
          for (std::size_t w = 0; w < words; ++w) rows[w] |= column[w];
        }
      }
    }
    auto& out = per_slice[std::size_t(z)];
    out.clear();
    out.reserve(std::size_t(nx) * std::size_t(ny));
    auto& cnt = counts[std::size_t(z)];
    std::vector<std::uint64_t> strong(words, 0);  // voxel row y's strong rows
    for (int y = 0; y < ny; ++y) {
      const AxisWeights ay = op.y_weights(z, y);
      const float row_cut = cutoff * peak_of(ay);
      std::size_t w0 = words, w1 = 0;  // the words holding strong rows: [w0, w1)
      for (const Segment& s : ay.segments) {
        for (int r = 0; r < s.length; ++r) {
          if (!(ay.table[s.offset + std::size_t(r)] > row_cut)) continue;
          const std::size_t w = std::size_t(s.first + r) >> 6;
          strong[w] |= std::uint64_t(1) << ((s.first + r) & 63);
          w0 = std::min(w0, w);
          w1 = std::max(w1, w + 1);
        }
      }
      for (int x = 0; x < nx; ++x) {
        const std::size_t v = g.index(x, y, z);
        if (!(op.normaliser(v) > 0.f)) {
          ++cnt[0];
          continue;
        }
        if (!in_region(g, settings.region, x, y, z)) {
          ++cnt[1];
          continue;
        }
        const std::uint64_t* rows = dark_rows.data() + std::size_t(x) * words;
        std::uint64_t hit = 0;
        for (std::size_t w = w0; w < w1; ++w) hit |= rows[w] & strong[w];
        if (hit) {
          ++cnt[2];
        } else {
          out.push_back(std::uint32_t(v));
        }
      }
      for (std::size_t w = w0; w < w1; ++w) strong[w] = 0;
    }
  });
  // Slices one after another, copied in parallel.
  std::vector<std::size_t> offset(std::size_t(nz) + 1, 0);
  for (int z = 0; z < nz; ++z) {
    const auto& s = per_slice[std::size_t(z)];
    if (s.empty()) ++report.slices_empty;
    offset[std::size_t(z) + 1] = offset[std::size_t(z)] + s.size();
    report.voxels_unseen += counts[std::size_t(z)][0];
    report.voxels_outside_region += counts[std::size_t(z)][1];
    report.voxels_dark += counts[std::size_t(z)][2];
  }
  active.resize(offset.back());  // not zeroed: the copies below write every element, on both threads
  tbb::parallel_for(0, nz, [&](int z) {
    const auto& s = per_slice[std::size_t(z)];
    std::copy(s.begin(), s.end(), active.begin() + std::ptrdiff_t(offset[std::size_t(z)]));
  });
  report.voxels_active = active.size();
}

}  // namespace plenopiv::recon::detail
