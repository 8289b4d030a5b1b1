// The vector field files of every producer (plenopiv process, correlate, --run, the daemon's run
// folders): one layout, HDF5 with vorticity, flags and provenance, and optionally .vti.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include "core/base/grid.hpp"
#include "core/io/hdf5_files.hpp"

namespace plenopiv::process {

// `h5`: /vectors (DESIGN.md layout) with vorticity_x/y/z (1/s) and flags (the correlation's
// per-node VectorFlag bits, uint8 with their legend; none when `flags` is empty), and /provenance
// with `provenance` beside what every file carries (io::write_vector_field_h5); `vti` (none when
// empty): the same field for ParaView with the vorticity vector. Both written atomically.
void write_vector_field_files(const std::filesystem::path& h5, const std::filesystem::path& vti,
                              const VectorField& field, std::span<const std::uint8_t> flags,
                              const std::vector<io::TextAttribute>& provenance = {});

// A provenance entry for an input file: {name, "<path> (CRC-32 <hex>, <n> bytes)"}, the path as
// given; InputError naming the file when it cannot be read.
io::TextAttribute input_file_entry(const std::string& name, const std::filesystem::path& file);

}  // namespace plenopiv::process
