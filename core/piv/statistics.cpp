// Running mean and RMS fluctuation of u, v, w per node over a run (Welford), valid vectors only.
#include "core/piv/statistics.hpp"

#include <cmath>

#include "core/base/errors.hpp"

namespace plenopiv::piv {

void RunningStatistics::add(const VectorField& field) {
  if (!(field.dt_s > 0)) throw InputError("statistics: vector field has no pulse separation (dt_s)");
  if (fields_ == 0) {
    grid_ = field.grid;
    count_.assign(grid_.count(), 0);
    for (int c = 0; c < 3; ++c) {
      mean_[c].assign(grid_.count(), 0.0);
      m2_[c].assign(grid_.count(), 0.0);
    }
  } else if (!(field.grid == grid_)) {
    throw InputError("statistics: vector field grid differs from the run's first field");
  }
  ++fields_;
  const std::array<const std::vector<float>*, 3> d{&field.dx_mm, &field.dy_mm, &field.dz_mm};
  const double to_m_s = 1e-3 / field.dt_s;
  for (std::size_t i = 0; i < count_.size(); ++i) {
    if (!field.valid[i]) continue;
    const double n = ++count_[i];
    for (int c = 0; c < 3; ++c) {
      const double x = (*d[c])[i] * to_m_s;
      const double delta = x - mean_[c][i];
      mean_[c][i] += delta / n;
      m2_[c][i] += delta * (x - mean_[c][i]);
    }
  }
}

std::vector<float> RunningStatistics::mean(int component) const {
  return std::vector<float>(mean_[component].begin(), mean_[component].end());
}

std::vector<float> RunningStatistics::rms(int component) const {
  std::vector<float> out(count_.size(), 0.f);
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (count_[i] > 0) out[i] = float(std::sqrt(m2_[component][i] / count_[i]));
  }
  return out;
}

}  // namespace plenopiv::piv
