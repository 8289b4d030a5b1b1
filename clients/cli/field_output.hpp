// The files `plenopiv process` writes for a vector field: HDF5 with vorticity and flags, and .vti.
#pragma once

#include <filesystem>
#include <vector>

#include "core/io/hdf5_files.hpp"
#include "core/piv/multipass.hpp"

namespace plenopiv::client {

// `h5`: /vectors (DESIGN.md layout) with vorticity_x/y/z (1/s), flags (the correlation's per-node
// bits) and the `text` attributes; `vti`: the same field for ParaView with the vorticity vector.
// Both written atomically.
void write_field_outputs(const std::filesystem::path& h5, const std::filesystem::path& vti,
                         const piv::CorrelationResult& result, const std::vector<io::TextAttribute>& text = {});

}  // namespace plenopiv::client
