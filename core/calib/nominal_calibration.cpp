// The nominal calibration: the camera file's lattice and the geometric white image of its lenses.
#include "core/calib/nominal_calibration.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace plenopiv::calib {

ImageF geometric_white_image(const optics::CameraModel& camera, const optics::MicrolensArray& lenses) {
  const optics::SensorSpec& s = camera.sensor();
  ImageF white(s.width_px, s.height_px, 0.f);
  const double radius_px = 0.5 * camera.microlens_image_diameter_px();
  const double s_i = camera.image_distance_mm();
  const double f_l = camera.microlens().focal_length_mm;
  constexpr int kSub = 8;  // sub-samples per pixel axis on the disk edge
  // Each lens paints its own disk; disks do not overlap (eq 7 is checked by CameraModel), but
  // neighbouring disks may touch a shared edge pixel. So the work is shared out by pixel rows,
  // each row painted by the lenses that reach it in lens order: no two threads write one pixel,
  // and a shared pixel gets its lenses' shares in the same order on every run.
  struct Spot {
    double cx, cy;
    int x0, x1;
  };
  std::vector<Spot> spots(lenses.centres_mm.size());
  std::vector<std::uint32_t> row_start(std::size_t(s.height_px) + 1, 0);
  std::vector<std::array<int, 2>> rows(spots.size());
  for (std::size_t lens = 0; lens < spots.size(); ++lens) {
    Spot& p = spots[lens];
    p.cx = optics::sensor_mm_to_column(s, optics::lens_centre_to_spot_mm(lenses.centres_mm[lens][0], s_i, f_l));
    p.cy = optics::sensor_mm_to_row(s, optics::lens_centre_to_spot_mm(lenses.centres_mm[lens][1], s_i, f_l));
    p.x0 = std::max(0, int(std::floor(p.cx - radius_px - 1)));
    p.x1 = std::min(s.width_px - 1, int(std::ceil(p.cx + radius_px + 1)));
    rows[lens] = {std::max(0, int(std::floor(p.cy - radius_px - 1))),
                  std::min(s.height_px - 1, int(std::ceil(p.cy + radius_px + 1)))};
    for (int y = rows[lens][0]; y <= rows[lens][1]; ++y) ++row_start[std::size_t(y) + 1];
  }
  for (std::size_t y = 0; y < std::size_t(s.height_px); ++y) row_start[y + 1] += row_start[y];
  std::vector<std::uint32_t> row_lenses(row_start.back());
  std::vector<std::uint32_t> fill(row_start.begin(), row_start.end() - 1);
  for (std::size_t lens = 0; lens < spots.size(); ++lens) {
    for (int y = rows[lens][0]; y <= rows[lens][1]; ++y) row_lenses[fill[std::size_t(y)]++] = std::uint32_t(lens);
  }
  // A pixel wholly inside (its centre within radius - 0.75) or outside (beyond radius + 0.75) is
  // told apart by its squared distance, with a margin that leaves hypot's answer to the pixels
  // near either bound; only the pixels between are sub-sampled.
  const double radius_sq = radius_px * radius_px;
  const double inner = radius_px - 0.75, outer = radius_px + 0.75, margin = 1e-9 * outer * outer;
  const double inner_sq = inner > 0 ? inner * inner : -1.0, outer_sq = outer * outer;
  tbb::parallel_for(0, s.height_px, [&](int y) {
    for (std::uint32_t k = row_start[std::size_t(y)]; k < row_start[std::size_t(y) + 1]; ++k) {
      const Spot& p = spots[row_lenses[k]];
      const double dy = y - p.cy;
      for (int x = p.x0; x <= p.x1; ++x) {
        const double dx = x - p.cx, d_sq = dx * dx + dy * dy;
        double fraction;
        if (d_sq < inner_sq - margin) {
          fraction = 1.0;
        } else if (d_sq > outer_sq + margin) {
          continue;
        } else if (const double d = std::hypot(dx, dy); d <= inner) {
          fraction = 1.0;
        } else if (d >= outer) {
          continue;
        } else {
          // The squared offsets of the sub-samples' columns and rows from the lens's centre, each
          // computed once: the sum of two of them is the sub-sample's squared distance.
          std::array<double, kSub> px_sq, py_sq;
          for (int i = 0; i < kSub; ++i) {
            const double px = x - 0.5 + (i + 0.5) / kSub - p.cx, py = y - 0.5 + (i + 0.5) / kSub - p.cy;
            px_sq[std::size_t(i)] = px * px;
            py_sq[std::size_t(i)] = py * py;
          }
          int inside = 0;
          for (int j = 0; j < kSub; ++j)
            for (int i = 0; i < kSub; ++i) inside += px_sq[std::size_t(i)] + py_sq[std::size_t(j)] <= radius_sq;
          fraction = double(inside) / (kSub * kSub);
        }
        float& w = white.at(x, y);
        w = std::min(1.f, w + float(fraction));
      }
    }
  });
  return white;
}

LoadedCalibration nominal_calibration(const optics::CameraModel& camera) {
  LoadedCalibration out;
  out.lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  out.white_correction = geometric_white_image(camera, out.lenses);
  return out;
}

}  // namespace plenopiv::calib
