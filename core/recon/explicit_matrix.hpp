// The weighting matrix W built literally, ray by ray, as a sparse matrix: the reference the
// matrix-free operators are tested against on small cases.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/recon/weights.hpp"

namespace plenopiv::recon {

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
// (4 lenses x 4 pixels) times the white image, normalised per voxel (eq 13). For small cases:
// it holds every non-zero weight.
SparseMatrix build_explicit_matrix(const WeightingOperator& op);

}  // namespace plenopiv::recon
