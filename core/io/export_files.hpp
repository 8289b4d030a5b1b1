// Exports of a vector field or volume file to the formats other tools read: Tecplot ASCII, NumPy
// .npz, CSV and NetCDF-4, each with the file's arrays, coordinates and units.
#pragma once

#include <filesystem>
#include <string>

#include "core/io/hdf5_files.hpp"

namespace plenopiv::io {

enum class ExportFormat { tecplot, npz, csv, netcdf };

// "tecplot", "npz", "csv" or "netcdf"; anything else is an InputError listing the choices.
ExportFormat export_format_from(const std::string& name);
// The file name extension of a format: ".dat", ".npz", ".csv", ".nc".
std::string export_extension(ExportFormat format);

// Writes `fields` (read by read_stored_fields_h5 from `source`, named in the files) to `out` in
// `format`, atomically. Every array of `fields` goes over, with the node coordinates x, y, z (mm):
// - tecplot: an ordered zone I, J, K = nx, ny, nz, DATAPACKING=POINT (x fastest), VARIABLES named
//   "name [units]"; a value that is NaN (no vector) is written as the dataset's auxiliary
//   `missing_value` (-1e30), which Tecplot's blanking can hide;
// - npz: one .npy per array, named as in HDF5 ([nz][ny][nx], float32 or uint8), x, y, z (float64),
//   `names` and `units` (string arrays: the i-th unit is the i-th name's), and `dt_s` for a field;
// - csv: one row per node (x fastest), a header "name (units)" per column, NaN as "nan";
// - netcdf: CF-style NetCDF-4: dimensions z, y, x, coordinate variables x, y, z (mm, axis X/Y/Z),
//   every array on (z, y, x) with units and long_name (and a flags `legend`), dt_s and the file's
//   provenance as global attributes.
// InputError: the folder of `out` missing; std::runtime_error for a failed write.
void export_fields(const StoredFields& fields, ExportFormat format, const std::filesystem::path& out,
                   const std::filesystem::path& source);

}  // namespace plenopiv::io
