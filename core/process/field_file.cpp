// The vector field files of every producer: HDF5 with vorticity, flags and provenance, and .vti.
#include "core/process/field_file.hpp"

#include <optional>

#include "core/base/errors.hpp"
#include "core/io/checksum.hpp"
#include "core/io/vtk_files.hpp"
#include "core/piv/derived.hpp"
#include "core/piv/peak_fit.hpp"

namespace plenopiv::process {

void write_vector_field_files(const std::filesystem::path& h5, const std::filesystem::path& vti,
                              const VectorField& field, std::span<const std::uint8_t> flags,
                              const std::vector<io::TextAttribute>& provenance) {
  if (!flags.empty() && flags.size() != field.grid.count())
    throw InputError(h5.string() + ": " + std::to_string(flags.size()) + " flags for " +
                     std::to_string(field.grid.count()) + " vectors");
  const auto omega = piv::vorticity(field);
  std::optional<io::FlagField> flag_field;
  if (!flags.empty())
    flag_field = io::FlagField{"flags", {flags.begin(), flags.end()}, std::string(piv::kVectorFlagLegend)};
  io::write_vector_field_h5(
      h5, field, {{"vorticity_x", omega[0], "1/s"}, {"vorticity_y", omega[1], "1/s"}, {"vorticity_z", omega[2], "1/s"}},
      provenance, flag_field);
  if (vti.empty()) return;
  std::vector<float> omega_vec(3 * omega[0].size());
  for (std::size_t i = 0; i < omega[0].size(); ++i)
    for (int c = 0; c < 3; ++c) omega_vec[3 * i + std::size_t(c)] = omega[std::size_t(c)][i];
  std::vector<io::NamedField> extra{{"vorticity_1_s_vec", omega_vec, "1/s"}};
  if (!flags.empty()) extra.push_back({"flags", std::vector<float>(flags.begin(), flags.end()), "1"});
  io::write_vector_field_vti(vti, field, extra);
}

io::TextAttribute input_file_entry(const std::string& name, const std::filesystem::path& file) {
  const io::FileChecksum sum = io::checksum_of_file(file);
  return {name, file.string() + " (CRC-32 " + io::crc32_hex(sum.crc32) + ", " + std::to_string(sum.bytes) + " bytes)"};
}

}  // namespace plenopiv::process
