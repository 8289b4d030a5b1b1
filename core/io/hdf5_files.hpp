// HDF5 files for volumes and vector fields, laid out as DESIGN.md says (h5py, MATLAB, ParaView).
#pragma once

#include <cstdint>
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
  std::string units;          // written as the dataset's `units` attribute ("1/s", "m/s", "1")
};

// Per-node bit flags stored as uint8 [nz][ny][nx] beside a field, with the meaning of each bit.
struct FlagField {
  std::string name;
  std::vector<std::uint8_t> bits;
  std::string legend;  // e.g. "1: parabolic fit; 2: ...", the dataset's `legend` attribute
};

// Every array these files hold carries a `units` attribute, and the 3-D ones, stored [nz][ny][nx]
// (C order: x varies fastest), have the 1-D voxel or node centre coordinates x, y, z (mm) attached
// as HDF5 dimension scales, so that xarray, netCDF readers and MATLAB see their coordinates; the
// group (or root) says so in `axis_order` and `axes`.
//
// A text attribute (name, value), e.g. one entry of a file's provenance.
using TextAttribute = std::pair<std::string, std::string>;

// Every file has a group /provenance of text attributes: software (plenopiv and its version),
// commit (git describe of the build), host, written_utc (ISO 8601), then the writer's entries
// (settings as YAML, inputs with their CRC-32, dt and how it was measured, ...).
//
// /volume float32 [nz][ny][nx] (units: arbitrary intensity) with attributes origin_mm (x, y, z of
// voxel [0][0][0]) and spacing_mm (dx, dy, dz); /x, /y, /z its dimension scales. Written atomically.
void write_volume_h5(const std::filesystem::path& path, const Volume& volume,
                     const std::vector<TextAttribute>& provenance = {});
// Reads it back; a file that is not HDF5 or lacks /volume or its attributes is an InputError.
Volume read_volume_h5(const std::filesystem::path& path);

// Group /vectors: 1-D axes x, y, z (mm, the dimension scales); on the [nz][ny][nx] grid dx, dy, dz
// (mm), u, v, w (m/s, from dt_s, which must be > 0), valid (uint8, 1: a measured or replaced vector),
// peak_ratio (NaN where no second peak was searched), sigma_u, sigma_v, sigma_w (m/s, the standard uncertainty; NaN
// where there is none; only when the field has its sigma; their long_name and the group's attribute sigma_method say
// what it holds), any `extra` fields and `flags`; attribute dt_s; /provenance with `provenance`.
// Written atomically.
void write_vector_field_h5(const std::filesystem::path& path, const VectorField& field,
                           const std::vector<NamedField>& extra = {}, const std::vector<TextAttribute>& provenance = {},
                           const std::optional<FlagField>& flags = std::nullopt);
VectorField read_vector_field_h5(const std::filesystem::path& path);
// One 3-D array of a file as stored, with what the file says about it.
struct StoredArray {
  std::string name;
  std::string units;          // the dataset's `units` ("" when it has none)
  std::string long_name;      // its `long_name` ("" when none)
  std::string legend;         // its `legend` (the meaning of flag bits; "" when none)
  bool is_uint8 = false;      // stored as uint8 (valid, flags): `values` then holds whole numbers 0..255
  std::vector<float> values;  // [nz][ny][nx]
};

// Everything on the grid of a vector field file (every 3-D dataset of /vectors, whatever its
// name: the layout's own, vorticity, flags, and any a newer writer adds) or of a volume file
// (/volume), for exporters that carry a file's arrays over whole.
struct StoredFields {
  std::string kind;                       // "vectors" or "volume"
  Grid3 grid;                             // the axes x, y, z (mm)
  std::optional<double> dt_s;             // a vector field's pulse separation
  std::vector<StoredArray> arrays;        // the layout's arrays first, in DESIGN.md's order, then the rest by name
  std::vector<TextAttribute> provenance;  // every entry of /provenance, by name
};
// InputError naming the file: missing, not HDF5, or with neither /vectors nor /volume.
StoredFields read_stored_fields_h5(const std::filesystem::path& path);

// An entry of a file's /provenance, or nullopt when it has none of that name (a file that cannot
// be opened, or has no /provenance, reads as having none).
std::optional<std::string> read_provenance(const std::filesystem::path& path, const std::string& name);

}  // namespace plenopiv::io
