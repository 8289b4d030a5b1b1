// The files `plenopiv process` and `correlate` write for a vector field: HDF5 with vorticity and flags, and .vti.
#include "clients/cli/field_output.hpp"

#include "core/io/vtk_files.hpp"
#include "core/piv/derived.hpp"
#include "core/piv/peak_fit.hpp"

namespace plenopiv::client {

void write_field_outputs(const std::filesystem::path& h5, const std::filesystem::path& vti,
                         const piv::CorrelationResult& r, const std::vector<io::TextAttribute>& text) {
  const auto omega = piv::vorticity(r.field);
  std::vector<float> flags(r.flags.begin(), r.flags.end());
  io::write_vector_field_h5(
      h5, r.field,
      {{"vorticity_x", omega[0], "1/s"}, {"vorticity_y", omega[1], "1/s"}, {"vorticity_z", omega[2], "1/s"}}, text,
      io::FlagField{"flags", r.flags, piv::kVectorFlagLegend});
  if (vti.empty()) return;
  std::vector<float> omega_vec(3 * omega[0].size());
  for (std::size_t i = 0; i < omega[0].size(); ++i)
    for (int c = 0; c < 3; ++c) omega_vec[3 * i + std::size_t(c)] = omega[std::size_t(c)][i];
  io::write_vector_field_vti(vti, r.field, {{"vorticity_1_s_vec", omega_vec}, {"flags", flags}});
}

}  // namespace plenopiv::client
