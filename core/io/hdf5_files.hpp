// HDF5 files for volumes and vector fields, laid out as DESIGN.md says (h5py, MATLAB, ParaView).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/base/grid.hpp"

namespace plenopiv::io {

// An extra float32 array on a vector field's grid (vorticity, say), written beside the others.
struct NamedField {
  std::string name;
  std::vector<float> values;  // [nz][ny][nx]
};

// /volume float32 [nz][ny][nx] with attributes origin_mm (x, y, z of voxel [0][0][0]) and
// spacing_mm (dx, dy, dz). Written atomically.
void write_volume_h5(const std::filesystem::path& path, const Volume& volume);
// Reads it back; a file that is not HDF5 or lacks /volume or its attributes is an InputError.
Volume read_volume_h5(const std::filesystem::path& path);

// A text attribute (name, value) of a file's group, e.g. where its inputs came from.
using TextAttribute = std::pair<std::string, std::string>;

// Group /vectors: 1-D axes x, y, z (mm); on the [nz][ny][nx] grid dx, dy, dz (mm), u, v, w (m/s,
// from dt_s, which must be > 0), valid (uint8), peak_ratio, and any `extra` fields; attribute
// dt_s, and the `text` attributes as strings. Written atomically.
void write_vector_field_h5(const std::filesystem::path& path, const VectorField& field,
                           const std::vector<NamedField>& extra = {}, const std::vector<TextAttribute>& text = {});
VectorField read_vector_field_h5(const std::filesystem::path& path);
// A text attribute of /vectors, or nullopt when the file has none of that name (or is no vector
// field file: a file that cannot be opened reads as having none).
std::optional<std::string> read_vector_field_text(const std::filesystem::path& path, const std::string& name);

}  // namespace plenopiv::io
