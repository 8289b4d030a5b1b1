// Regular 3-D grids in object space (mm) and the arrays that live on them: volumes, vector fields.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/base/big_buffer.hpp"
#include "core/base/memory.hpp"

namespace plenopiv {

// A regular grid, axes as DESIGN.md: x right, y down, z away from the camera, z = 0 at the
// nominal focal plane. Arrays on it are [z][y][x], x fastest.
struct Grid3 {
  std::array<int, 3> shape{0, 0, 0};          // nx, ny, nz
  std::array<double, 3> origin_mm{0, 0, 0};   // centre of node [0][0][0]: x, y, z
  std::array<double, 3> spacing_mm{1, 1, 1};  // dx, dy, dz

  std::size_t count() const { return std::size_t(shape[0]) * shape[1] * shape[2]; }
  std::size_t index(int x, int y, int z) const { return (std::size_t(z) * shape[1] + y) * shape[0] + x; }
  double coordinate_mm(int axis, int i) const { return origin_mm[axis] + i * spacing_mm[axis]; }
  bool operator==(const Grid3&) const = default;
  // count(), checked first against this machine's memory for `element_bytes` per node (and
  // `arrays` arrays of them): InputError naming the grid instead of std::bad_alloc.
  std::size_t checked_count(std::size_t element_bytes, std::size_t arrays = 1) const {
    const std::string what = "a grid of " + std::to_string(shape[0]) + " x " + std::to_string(shape[1]) + " x " +
                             std::to_string(shape[2]) + " nodes";
    return plenopiv::checked_count(shape[0], shape[1], double(shape[2]) * double(arrays), element_bytes, what) / arrays;
  }
};

// Reconstructed (or exact) particle intensity, float32.
struct Volume {
  Grid3 grid;
  HugePageVector<float> data;  // [z][y][x]

  Volume() = default;
  explicit Volume(const Grid3& g, float fill = 0.f) : grid(g), data(g.checked_count(sizeof(float)), fill) {}
  float& at(int x, int y, int z) { return data[grid.index(x, y, z)]; }
  float at(int x, int y, int z) const { return data[grid.index(x, y, z)]; }
};

// Displacements (mm) on their own grid, with validity and correlation quality per node.
struct VectorField {
  Grid3 grid;
  std::vector<float> dx_mm, dy_mm, dz_mm;
  std::vector<std::uint8_t> valid;
  // Primary over secondary correlation peak; NaN where the final pass took the peak at the
  // predictor without a search for others (CorrelationSettings::final_peak_search).
  std::vector<float> peak_ratio;
  // Standard uncertainty of dx, dy, dz (mm) per node: empty when not estimated; NaN at a node
  // without an estimate (invalid, or replaced by its neighbours' mean).
  std::vector<float> sigma_dx_mm, sigma_dy_mm, sigma_dz_mm;
  // What the sigma arrays hold and leave out, in words (the files write it beside them); empty
  // without them.
  std::string sigma_method;
  double dt_s = 0.0;  // pulse separation; velocity = displacement / dt

  // The uncertainty estimated: all three sigma arrays hold a value per node.
  bool has_sigma() const {
    const std::size_t n = dz_mm.size();
    return sigma_dx_mm.size() == n && sigma_dy_mm.size() == n && sigma_dz_mm.size() == n;
  }

  VectorField() = default;
  explicit VectorField(const Grid3& g)
      : grid(g),
        dx_mm(g.checked_count(sizeof(float), 5), 0.f),
        dy_mm(g.count(), 0.f),
        dz_mm(g.count(), 0.f),
        valid(g.count(), 0),
        peak_ratio(g.count(), 0.f) {}
};

}  // namespace plenopiv
