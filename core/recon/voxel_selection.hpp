// Which voxels a reconstruction solves: the image thresholded to dark and lit pixels, and the
// voxels no dark pixel rules out (eq 9), inside the region and the field of view. Internal to
// core/recon.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "core/base/big_buffer.hpp"
#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::recon::detail {

// The image MART sees, in `out`: pixels at or below the noise threshold become 0.
void threshold_image(const ImageF& image, float threshold, BigBuffer<float>& out);

// Whether voxel (x, y, z) of `g` lies in `region` (always, without one).
bool in_region(const Grid3& g, const std::optional<RegionMm>& region, int x, int y, int z);

// select_active's largest arrays, kept across frames.
struct SelectScratch {
  std::vector<std::uint64_t> dark;                    // dark pixels as bits, per sensor column
  std::vector<std::vector<std::uint32_t>> per_slice;  // each slice's active voxels
};

// Voxels MART can change: seen by some pixel, inside the region, and seen by no dark pixel (a
// dark pixel's ratio is 0, so eq 9 zeroes every voxel it sees and they stay zero). "Seen" here:
// a pixel where both the voxel's column weight and its row weight exceed the cutoff's fraction
// of their largest value.
//
// The test is separable: voxel (x, y) of slice z is dark when some row r among y's strong rows
// holds a dark pixel in one of x's strong columns. So the dark pixels are kept column by column
// as bits over the sensor rows; per voxel column x the OR of its strong columns' bits gives the
// rows where x meets a dark pixel, per voxel row y its strong rows are bits too, and each voxel
// costs one AND over the words of y's strong rows.
// Fills the voxel and pixel counts of `report`; `active` becomes the active voxels, increasing (in
// its own storage: a list kept from frame to frame is not allocated or faulted in again).
void select_active(const WeightingOperator& op, std::span<const float> image, const MartSettings& settings,
                   SelectScratch& scratch, SkipReport& report, BigBuffer<std::uint32_t>& active);

}  // namespace plenopiv::recon::detail
