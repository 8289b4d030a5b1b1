// Running mean and RMS fluctuation of u, v, w per node over a run (Welford), valid vectors only.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/base/grid.hpp"

namespace plenopiv::piv {

class RunningStatistics {
 public:
  // Adds one field's velocities (displacement / field.dt_s, in m/s) at its valid nodes. The first
  // field fixes the grid; a field on another grid is an InputError.
  void add(const VectorField& field);

  std::uint64_t fields() const { return fields_; }
  const Grid3& grid() const { return grid_; }
  // Per node: number of valid samples, mean (m/s) and RMS fluctuation (population, m/s) of u, v, w.
  const std::vector<std::uint32_t>& count() const { return count_; }
  std::vector<float> mean(int component) const;
  std::vector<float> rms(int component) const;

 private:
  Grid3 grid_;
  std::uint64_t fields_ = 0;
  std::vector<std::uint32_t> count_;
  std::array<std::vector<double>, 3> mean_, m2_;
};

}  // namespace plenopiv::piv
