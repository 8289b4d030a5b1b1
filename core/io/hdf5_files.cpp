// HDF5 files for volumes and vector fields, laid out as DESIGN.md says (h5py, MATLAB, ParaView).
#include "core/io/hdf5_files.hpp"

#include <hdf5.h>
#include <hdf5_hl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <ctime>
#include <optional>
#include <stdexcept>

#include "core/base/build_info.hpp"
#include "core/base/errors.hpp"
#include "core/base/memory.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/hdf5_handle.hpp"

namespace plenopiv::io {
namespace {

using Handle = Hdf5Handle;

// A failed write is the disk's failure, not the input's (write_atomically names a full disk).
void check(herr_t status, const std::filesystem::path& path, const std::string& what) {
  if (status < 0) throw std::runtime_error(path.string() + ": HDF5: cannot " + what);
}

// Writes what HDF5 still buffers: a failure at close would otherwise go unnoticed.
void flush(hid_t file, const std::filesystem::path& path) { check(H5Fflush(file, H5F_SCOPE_GLOBAL), path, "write"); }

template <typename T>
hid_t mem_type() {
  if constexpr (std::is_same_v<T, float>) return H5T_NATIVE_FLOAT;
  if constexpr (std::is_same_v<T, double>) return H5T_NATIVE_DOUBLE;
  if constexpr (std::is_same_v<T, std::uint8_t>) return H5T_NATIVE_UINT8;
}
template <typename T>
hid_t file_type() {
  if constexpr (std::is_same_v<T, float>) return H5T_IEEE_F32LE;
  if constexpr (std::is_same_v<T, double>) return H5T_IEEE_F64LE;
  if constexpr (std::is_same_v<T, std::uint8_t>) return H5T_STD_U8LE;
}

template <typename T>
void write_dataset(hid_t parent, const std::filesystem::path& path, const std::string& name,
                   const std::vector<hsize_t>& dims, const T* data) {
  Handle space(H5Screate_simple(int(dims.size()), dims.data(), nullptr), H5Sclose);
  Handle set(H5Dcreate2(parent, name.c_str(), file_type<T>(), space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
             H5Dclose);
  if (!set.ok()) throw InputError(path.string() + ": HDF5: cannot create dataset " + name);
  check(H5Dwrite(set.get(), mem_type<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, data), path, "write dataset " + name);
}

void write_attribute(hid_t parent, const std::filesystem::path& path, const std::string& name, const double* values,
                     hsize_t count) {
  Handle space(H5Screate_simple(1, &count, nullptr), H5Sclose);
  Handle attr(H5Acreate2(parent, name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) throw InputError(path.string() + ": HDF5: cannot create attribute " + name);
  check(H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, values), path, "write attribute " + name);
}

// A fixed-length, NUL-terminated string type that holds `value` (at least one byte).
Handle text_type(const std::filesystem::path& path, const std::string& value) {
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  check(H5Tset_size(type.get(), std::max<std::size_t>(value.size(), 1)), path, "make a string type");
  check(H5Tset_strpad(type.get(), H5T_STR_NULLTERM), path, "make a string type");
  return type;
}

void write_text_attribute(hid_t parent, const std::filesystem::path& path, const std::string& name,
                          const std::string& value) {
  const Handle type = text_type(path, value);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(parent, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) throw std::runtime_error(path.string() + ": HDF5: cannot create attribute " + name);
  const std::string padded = value.empty() ? std::string(1, '\0') : value;
  check(H5Awrite(attr.get(), type.get(), padded.data()), path, "write attribute " + name);
}

// A text too long for an attribute (HDF5 keeps attributes under 64 KiB in the object header), as a
// scalar string dataset `name` of `parent`.
void write_text_dataset(hid_t parent, const std::filesystem::path& path, const std::string& name,
                        const std::string& value) {
  const Handle type = text_type(path, value);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle set(H5Dcreate2(parent, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
             H5Dclose);
  if (!set.ok()) throw std::runtime_error(path.string() + ": HDF5: cannot create dataset " + name);
  const std::string padded = value.empty() ? std::string(1, '\0') : value;
  check(H5Dwrite(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, padded.data()), path, "write " + name);
}

// The axes' meaning, for the group that holds 3-D arrays.
constexpr const char* kAxisOrder = "z, y, x: arrays are [nz][ny][nx] (C order, x fastest; MATLAB shows them x, y, z)";
constexpr const char* kAxes =
    "x right, y down on the sensor, z away from the camera along the optical axis; mm; z = 0 the nominal focal plane";

// A sigma array's long_name: what it is, and its method (VectorField::sigma_method; a field read
// from a file written before it was kept says only its statistic).
std::string sigma_long_name(const std::string& component, const std::string& method) {
  return "standard uncertainty of " + component + " (" +
         (method.empty() ? std::string("correlation statistics, Wieneke 2015") : method) +
         "); NaN: no estimate (invalid or interpolated)";
}

void write_units(hid_t parent, const std::filesystem::path& path, const std::string& name, const std::string& units,
                 const std::string& description = {}) {
  Handle set(H5Dopen2(parent, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!set.ok()) throw std::runtime_error(path.string() + ": HDF5: cannot open dataset " + name);
  write_text_attribute(set.get(), path, "units", units);
  if (!description.empty()) write_text_attribute(set.get(), path, "long_name", description);
}

// Writes the 1-D coordinates x, y, z (mm, voxel or node centres) into `parent` and makes them
// dimension scales.
void write_axes(hid_t parent, const std::filesystem::path& path, const Grid3& grid) {
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    std::vector<double> axis(std::size_t(grid.shape[a]));
    for (int i = 0; i < grid.shape[a]; ++i) axis[std::size_t(i)] = grid.coordinate_mm(a, i);
    write_dataset(parent, path, names[a], {hsize_t(axis.size())}, axis.data());
    Handle set(H5Dopen2(parent, names[a], H5P_DEFAULT), H5Dclose);
    check(H5DSset_scale(set.get(), names[a]), path, std::string("make ") + names[a] + " a dimension scale");
    write_text_attribute(set.get(), path, "units", "mm");
  }
  write_text_attribute(parent, path, "axis_order", kAxisOrder);
  write_text_attribute(parent, path, "axes", kAxes);
}

// Attaches z, y, x (in `parent`) to dimensions 0, 1, 2 of the 3-D dataset `name`.
void attach_axes(hid_t parent, const std::filesystem::path& path, const std::string& name) {
  Handle set(H5Dopen2(parent, name.c_str(), H5P_DEFAULT), H5Dclose);
  const char* names[3] = {"z", "y", "x"};
  for (unsigned dim = 0; dim < 3; ++dim) {
    Handle scale(H5Dopen2(parent, names[dim], H5P_DEFAULT), H5Dclose);
    check(H5DSattach_scale(set.get(), scale.get(), dim), path, "attach " + std::string(names[dim]) + " to " + name);
  }
}

// Group /provenance: what made the file (software, commit, host, time written, UTC) and the
// caller's `entries` (settings, inputs and their checksums, dt and its source), all as text
// attributes.
void write_provenance(hid_t file, const std::filesystem::path& path, const std::vector<TextAttribute>& entries) {
  Handle group(H5Gcreate2(file, "provenance", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
  if (!group.ok()) throw std::runtime_error(path.string() + ": HDF5: cannot create group /provenance");
  char host[256] = {};
  if (gethostname(host, sizeof host - 1) != 0) std::strcpy(host, "unknown");
  char written[32] = {};
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  std::strftime(written, sizeof written, "%Y-%m-%dT%H:%M:%SZ", &utc);
  write_text_attribute(group.get(), path, "software", "plenopiv " + std::string(build_version()));
  write_text_attribute(group.get(), path, "commit", std::string(build_commit()));
  write_text_attribute(group.get(), path, "host", host);
  write_text_attribute(group.get(), path, "written_utc", written);
  // Entries up to 32 KiB are attributes; longer ones (a large settings file) string datasets.
  for (const auto& [name, value] : entries) {
    if (value.size() <= 32 * 1024) {
      write_text_attribute(group.get(), path, name, value);
    } else {
      write_text_dataset(group.get(), path, name, value);
    }
  }
}

std::vector<double> read_attribute(hid_t parent, const std::filesystem::path& path, const std::string& owner,
                                   const std::string& name, hsize_t expected) {
  if (H5Aexists(parent, name.c_str()) <= 0) {
    throw InputError(path.string() + ": " + owner + " has no attribute " + name);
  }
  Handle attr(H5Aopen(parent, name.c_str(), H5P_DEFAULT), H5Aclose);
  Handle space(H5Aget_space(attr.get()), H5Sclose);
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n != hssize_t(expected)) {
    throw InputError(path.string() + ": " + owner + " attribute " + name + " has " + std::to_string(n) +
                     " values, expected " + std::to_string(expected));
  }
  std::vector<double> values(expected);
  check(H5Aread(attr.get(), H5T_NATIVE_DOUBLE, values.data()), path, "read attribute " + name);
  return values;
}

// Reads a dataset whose shape must be `dims`; wrong shape or a missing dataset names the file.
template <typename T, typename Array = std::vector<T>>
Array read_dataset(hid_t parent, const std::filesystem::path& path, const std::string& name,
                   std::vector<hsize_t>* dims_out, const std::vector<hsize_t>* expected) {
  if (H5Lexists(parent, name.c_str(), H5P_DEFAULT) <= 0) {
    throw InputError(path.string() + ": no dataset " + name);
  }
  Handle set(H5Dopen2(parent, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!set.ok()) throw InputError(path.string() + ": cannot open dataset " + name);
  Handle space(H5Dget_space(set.get()), H5Sclose);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  std::vector<hsize_t> dims(std::max(rank, 0));
  H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr);
  if (expected && dims != *expected) {
    throw InputError(path.string() + ": dataset " + name + " has the wrong shape");
  }
  // A damaged file can declare any shape (its chunks unwritten, read as the fill value): the count
  // is formed in floating point, so that it cannot wrap, and checked against this machine's memory.
  double count = 1;
  for (hsize_t d : dims) count *= double(d);
  require_memory(count * sizeof(T), path.string() + ": dataset " + name);
  Array data(static_cast<std::size_t>(count));
  check(H5Dread(set.get(), mem_type<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), path, "read dataset " + name);
  if (dims_out) *dims_out = dims;
  return data;
}

Handle open_for_reading(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) throw InputError(path.string() + ": no such file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw InputError(path.string() + ": not an HDF5 file");
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.ok()) throw InputError(path.string() + ": cannot open HDF5 file (corrupt?)");
  return file;
}

std::vector<hsize_t> dims_of(const Grid3& g) { return {hsize_t(g.shape[2]), hsize_t(g.shape[1]), hsize_t(g.shape[0])}; }

void check_grid(const Grid3& g, std::size_t size, const std::string& what) {
  for (int a = 0; a < 3; ++a) {
    if (g.shape[a] <= 0) throw InputError(what + ": grid shape must be positive");
    if (!(g.spacing_mm[a] > 0)) throw InputError(what + ": grid spacing must be positive");
  }
  if (size != g.count()) throw InputError(what + ": array size does not match the grid");
}

}  // namespace

void write_volume_h5(const std::filesystem::path& path, const Volume& volume,
                     const std::vector<TextAttribute>& provenance) {
  check_grid(volume.grid, volume.data.size(), path.string() + ": volume");
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    Handle file(H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.ok()) throw InputError(path.string() + ": cannot create HDF5 file");
    write_dataset(file.get(), path, "volume", dims_of(volume.grid), volume.data.data());
    {
      Handle set(H5Dopen2(file.get(), "volume", H5P_DEFAULT), H5Dclose);
      write_attribute(set.get(), path, "origin_mm", volume.grid.origin_mm.data(), 3);
      write_attribute(set.get(), path, "spacing_mm", volume.grid.spacing_mm.data(), 3);
    }
    write_units(file.get(), path, "volume", "arbitrary (reconstructed intensity)",
                "particle intensity per voxel (MART)");
    write_axes(file.get(), path, volume.grid);
    attach_axes(file.get(), path, "volume");
    write_provenance(file.get(), path, provenance);
    flush(file.get(), path);
  });
}

Volume read_volume_h5(const std::filesystem::path& path) {
  Handle file = open_for_reading(path);
  std::vector<hsize_t> dims;
  HugePageVector<float> data = read_dataset<float, HugePageVector<float>>(file.get(), path, "volume", &dims, nullptr);
  if (dims.size() != 3) throw InputError(path.string() + ": /volume is not 3-D [nz][ny][nx]");
  Handle set(H5Dopen2(file.get(), "volume", H5P_DEFAULT), H5Dclose);
  const auto origin = read_attribute(set.get(), path, "/volume", "origin_mm", 3);
  const auto spacing = read_attribute(set.get(), path, "/volume", "spacing_mm", 3);
  Volume v;
  v.grid.shape = {int(dims[2]), int(dims[1]), int(dims[0])};
  for (int a = 0; a < 3; ++a) {
    v.grid.origin_mm[a] = origin[a];
    v.grid.spacing_mm[a] = spacing[a];
  }
  v.data = std::move(data);
  check_grid(v.grid, v.data.size(), path.string() + ": /volume");
  return v;
}

void write_vector_field_h5(const std::filesystem::path& path, const VectorField& f,
                           const std::vector<NamedField>& extra, const std::vector<TextAttribute>& provenance,
                           const std::optional<FlagField>& flags) {
  const std::string what = path.string() + ": vector field";
  check_grid(f.grid, f.dx_mm.size(), what);
  for (const auto* v : {&f.dy_mm, &f.dz_mm, &f.peak_ratio}) check_grid(f.grid, v->size(), what);
  check_grid(f.grid, f.valid.size(), what);
  for (const NamedField& e : extra) check_grid(f.grid, e.values.size(), what + " field " + e.name);
  const bool sigma = !f.sigma_dx_mm.empty() || !f.sigma_dy_mm.empty() || !f.sigma_dz_mm.empty();
  if (sigma)
    for (const auto* v : {&f.sigma_dx_mm, &f.sigma_dy_mm, &f.sigma_dz_mm})
      check_grid(f.grid, v->size(), what + " sigma");
  if (flags) check_grid(f.grid, flags->bits.size(), what + " field " + flags->name);
  if (!(f.dt_s > 0)) throw InputError(what + ": dt_s must be > 0 to give velocities");

  write_atomically(path, [&](const std::filesystem::path& tmp) {
    Handle file(H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.ok()) throw InputError(path.string() + ": cannot create HDF5 file");
    Handle group(H5Gcreate2(file.get(), "vectors", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
    write_axes(group.get(), path, f.grid);
    const auto dims = dims_of(f.grid);
    // Each 3-D array: its name, units and meaning.
    std::vector<std::array<std::string, 3>> fields;
    write_dataset(group.get(), path, "dx", dims, f.dx_mm.data());
    write_dataset(group.get(), path, "dy", dims, f.dy_mm.data());
    write_dataset(group.get(), path, "dz", dims, f.dz_mm.data());
    for (const char* c : {"x", "y", "z"})
      fields.push_back({std::string("d") + c, "mm", std::string("displacement along ") + c + " between the pulses"});
    // mm / s -> m/s
    const double scale = 1e-3 / f.dt_s;
    std::vector<float> velocity(f.grid.count());
    const std::pair<const char*, const std::vector<float>*> comps[3] = {
        {"u", &f.dx_mm}, {"v", &f.dy_mm}, {"w", &f.dz_mm}};
    for (const auto& [name, disp] : comps) {
      for (std::size_t i = 0; i < velocity.size(); ++i) velocity[i] = float((*disp)[i] * scale);
      write_dataset(group.get(), path, name, dims, velocity.data());
    }
    fields.push_back({"u", "m/s", "velocity along x"});
    fields.push_back({"v", "m/s", "velocity along y"});
    fields.push_back({"w", "m/s", "velocity along z"});
    if (sigma) {
      const std::pair<const char*, const std::vector<float>*> sigmas[3] = {
          {"sigma_u", &f.sigma_dx_mm}, {"sigma_v", &f.sigma_dy_mm}, {"sigma_w", &f.sigma_dz_mm}};
      for (const auto& [name, s] : sigmas) {
        for (std::size_t i = 0; i < velocity.size(); ++i) velocity[i] = float((*s)[i] * scale);
        write_dataset(group.get(), path, name, dims, velocity.data());
        fields.push_back({name, "m/s", sigma_long_name(name + 6, f.sigma_method)});
      }
    }
    write_dataset(group.get(), path, "valid", dims, f.valid.data());
    fields.push_back({"valid", "1", "1: a vector (measured, or replaced by validation); 0: none"});
    write_dataset(group.get(), path, "peak_ratio", dims, f.peak_ratio.data());
    fields.push_back({"peak_ratio", "1",
                      "primary over secondary correlation peak (NaN: peak taken at the predictor, no second one "
                      "searched)"});
    for (const NamedField& e : extra) {
      write_dataset(group.get(), path, e.name, dims, e.values.data());
      fields.push_back({e.name, e.units.empty() ? "1" : e.units, ""});
    }
    if (flags) {
      write_dataset(group.get(), path, flags->name, dims, flags->bits.data());
      fields.push_back({flags->name, "1", "bit flags per vector"});
      Handle set(H5Dopen2(group.get(), flags->name.c_str(), H5P_DEFAULT), H5Dclose);
      write_text_attribute(set.get(), path, "legend", flags->legend);
    }
    for (const auto& [name, units, meaning] : fields) {
      write_units(group.get(), path, name, units, meaning);
      attach_axes(group.get(), path, name);
    }
    if (sigma && !f.sigma_method.empty()) write_text_attribute(group.get(), path, "sigma_method", f.sigma_method);
    write_attribute(group.get(), path, "dt_s", &f.dt_s, 1);
    write_attribute(group.get(), path, "origin_mm", f.grid.origin_mm.data(), 3);
    write_attribute(group.get(), path, "spacing_mm", f.grid.spacing_mm.data(), 3);
    write_provenance(file.get(), path, provenance);
    flush(file.get(), path);
  });
}

namespace {
std::string text_attribute(hid_t object, const char* name);  // below
}  // namespace

VectorField read_vector_field_h5(const std::filesystem::path& path) {
  Handle file = open_for_reading(path);
  if (H5Lexists(file.get(), "vectors", H5P_DEFAULT) <= 0) {
    throw InputError(path.string() + ": no group /vectors (not a plenopiv vector field file)");
  }
  Handle group(H5Gopen2(file.get(), "vectors", H5P_DEFAULT), H5Gclose);
  VectorField f;
  const auto origin = read_attribute(group.get(), path, "/vectors", "origin_mm", 3);
  const auto spacing = read_attribute(group.get(), path, "/vectors", "spacing_mm", 3);
  f.dt_s = read_attribute(group.get(), path, "/vectors", "dt_s", 1)[0];
  std::vector<hsize_t> dims;
  f.dx_mm = read_dataset<float>(group.get(), path, "dx", &dims, nullptr);
  if (dims.size() != 3) throw InputError(path.string() + ": /vectors/dx is not 3-D");
  f.grid.shape = {int(dims[2]), int(dims[1]), int(dims[0])};
  for (int a = 0; a < 3; ++a) {
    f.grid.origin_mm[a] = origin[a];
    f.grid.spacing_mm[a] = spacing[a];
  }
  f.dy_mm = read_dataset<float>(group.get(), path, "dy", nullptr, &dims);
  f.dz_mm = read_dataset<float>(group.get(), path, "dz", nullptr, &dims);
  f.valid = read_dataset<std::uint8_t>(group.get(), path, "valid", nullptr, &dims);
  f.peak_ratio = read_dataset<float>(group.get(), path, "peak_ratio", nullptr, &dims);
  // The uncertainty, when the file has it (m/s -> mm).
  if (H5Lexists(group.get(), "sigma_u", H5P_DEFAULT) > 0) {
    const double to_mm = f.dt_s * 1e3;
    const std::pair<const char*, std::vector<float>*> sigmas[3] = {
        {"sigma_u", &f.sigma_dx_mm}, {"sigma_v", &f.sigma_dy_mm}, {"sigma_w", &f.sigma_dz_mm}};
    for (const auto& [name, s] : sigmas) {
      *s = read_dataset<float>(group.get(), path, name, nullptr, &dims);
      for (float& v : *s) v = float(v * to_mm);
    }
    f.sigma_method = text_attribute(group.get(), "sigma_method");
  }
  check_grid(f.grid, f.dx_mm.size(), path.string() + ": /vectors");
  return f;
}

namespace {

// A fixed-length string of up to `limit` bytes read by `read` into a buffer of the type's size;
// nullopt when `type` is no such string or the read fails.
template <typename Read>
std::optional<std::string> read_fixed_text(hid_t type, std::size_t limit, Read read) {
  if (H5Tget_class(type) != H5T_STRING || H5Tis_variable_str(type) > 0) return std::nullopt;
  const std::size_t size = H5Tget_size(type);
  if (size == 0 || size > limit) return std::nullopt;
  std::string value(size, '\0');
  if (read(value.data()) < 0) return std::nullopt;
  value.resize(std::strlen(value.c_str()));
  return value;
}

}  // namespace

std::optional<std::string> read_provenance(const std::filesystem::path& path, const std::string& name) {
  if (!std::filesystem::is_regular_file(path) || H5Fis_hdf5(path.c_str()) <= 0) return std::nullopt;
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.ok() || H5Lexists(file.get(), "provenance", H5P_DEFAULT) <= 0) return std::nullopt;
  Handle group(H5Gopen2(file.get(), "provenance", H5P_DEFAULT), H5Gclose);
  if (!group.ok()) return std::nullopt;
  if (H5Aexists(group.get(), name.c_str()) > 0) {
    Handle attr(H5Aopen(group.get(), name.c_str(), H5P_DEFAULT), H5Aclose);
    if (!attr.ok()) return std::nullopt;
    Handle type(H5Aget_type(attr.get()), H5Tclose);
    return read_fixed_text(type.get(), 1u << 20, [&](char* out) { return H5Aread(attr.get(), type.get(), out); });
  }
  // A long entry is a string dataset.
  if (name.empty() || name.find('/') != std::string::npos || H5Lexists(group.get(), name.c_str(), H5P_DEFAULT) <= 0)
    return std::nullopt;
  Handle set(H5Dopen2(group.get(), name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!set.ok()) return std::nullopt;
  Handle type(H5Dget_type(set.get()), H5Tclose);
  return read_fixed_text(type.get(), 64u << 20,
                         [&](char* out) { return H5Dread(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, out); });
}

namespace {

// A text attribute of `object`, "" when it has none (or it is no fixed-length string).
std::string text_attribute(hid_t object, const char* name) {
  if (H5Aexists(object, name) <= 0) return "";
  Handle attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) return "";
  Handle type(H5Aget_type(attr.get()), H5Tclose);
  return read_fixed_text(type.get(), 1u << 20, [&](char* out) { return H5Aread(attr.get(), type.get(), out); })
      .value_or("");
}

// The names of a group's links, in name order.
std::vector<std::string> link_names(hid_t group) {
  std::vector<std::string> names;
  H5Literate(
      group, H5_INDEX_NAME, H5_ITER_INC, nullptr,
      [](hid_t, const char* name, const H5L_info_t*, void* data) -> herr_t {
        static_cast<std::vector<std::string>*>(data)->push_back(name);
        return 0;
      },
      &names);
  return names;
}

// The names of an object's attributes, in name order.
std::vector<std::string> attribute_names(hid_t object) {
  std::vector<std::string> names;
  H5Aiterate2(
      object, H5_INDEX_NAME, H5_ITER_INC, nullptr,
      [](hid_t, const char* name, const H5A_info_t*, void* data) -> herr_t {
        static_cast<std::vector<std::string>*>(data)->push_back(name);
        return 0;
      },
      &names);
  return names;
}

// The 3-D dataset `name` of `parent` if it lies on the grid `dims` and holds numbers; nullopt for
// anything else (axes, strings, other shapes).
std::optional<StoredArray> stored_array(hid_t parent, const std::filesystem::path& path, const std::string& name,
                                        const std::vector<hsize_t>& dims) {
  Handle set(H5Dopen2(parent, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!set.ok()) return std::nullopt;
  Handle space(H5Dget_space(set.get()), H5Sclose);
  if (H5Sget_simple_extent_ndims(space.get()) != 3) return std::nullopt;
  std::vector<hsize_t> shape(3);
  H5Sget_simple_extent_dims(space.get(), shape.data(), nullptr);
  if (shape != dims) return std::nullopt;
  Handle type(H5Dget_type(set.get()), H5Tclose);
  const H5T_class_t type_class = H5Tget_class(type.get());
  if (type_class != H5T_INTEGER && type_class != H5T_FLOAT) return std::nullopt;
  StoredArray a;
  a.name = name;
  a.is_uint8 = type_class == H5T_INTEGER && H5Tget_size(type.get()) == 1 && H5Tget_sign(type.get()) == H5T_SGN_NONE;
  a.values.resize(std::size_t(dims[0] * dims[1] * dims[2]));
  check(H5Dread(set.get(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, a.values.data()), path,
        "read dataset " + name);
  a.units = text_attribute(set.get(), "units");
  a.long_name = text_attribute(set.get(), "long_name");
  a.legend = text_attribute(set.get(), "legend");
  return a;
}

}  // namespace

StoredFields read_stored_fields_h5(const std::filesystem::path& path) {
  Handle file = open_for_reading(path);
  StoredFields out;
  const bool vectors = H5Lexists(file.get(), "vectors", H5P_DEFAULT) > 0;
  if (!vectors && H5Lexists(file.get(), "volume", H5P_DEFAULT) <= 0)
    throw InputError(path.string() + ": neither /vectors nor /volume (not a plenopiv vector field or volume file)");
  out.kind = vectors ? "vectors" : "volume";
  Handle group(vectors ? H5Gopen2(file.get(), "vectors", H5P_DEFAULT) : H5Gopen2(file.get(), "/", H5P_DEFAULT),
               H5Gclose);
  if (!group.ok()) throw InputError(path.string() + ": cannot open /" + (vectors ? "vectors" : ""));
  const std::string first = vectors ? "dx" : "volume";
  std::vector<hsize_t> dims;
  read_dataset<float>(group.get(), path, first, &dims, nullptr);
  if (dims.size() != 3) throw InputError(path.string() + ": /" + (vectors ? "vectors/" : "") + first + " is not 3-D");
  {
    Handle owner(vectors ? H5Gopen2(file.get(), "vectors", H5P_DEFAULT) : H5Dopen2(file.get(), "volume", H5P_DEFAULT),
                 vectors ? H5Gclose : H5Dclose);
    const std::string owner_name = vectors ? "/vectors" : "/volume";
    const auto origin = read_attribute(owner.get(), path, owner_name, "origin_mm", 3);
    const auto spacing = read_attribute(owner.get(), path, owner_name, "spacing_mm", 3);
    out.grid.shape = {int(dims[2]), int(dims[1]), int(dims[0])};
    for (int a = 0; a < 3; ++a) {
      out.grid.origin_mm[a] = origin[a];
      out.grid.spacing_mm[a] = spacing[a];
    }
    if (vectors) out.dt_s = read_attribute(owner.get(), path, owner_name, "dt_s", 1)[0];
  }
  check_grid(out.grid, std::size_t(dims[0] * dims[1] * dims[2]), path.string() + ": /" + out.kind);
  // The layout's arrays in their documented order, then whatever else lies on the grid.
  const std::vector<std::string> layout =
      vectors ? std::vector<std::string>{"dx", "dy", "dz", "u", "v", "w", "valid", "peak_ratio"}
              : std::vector<std::string>{"volume"};
  std::vector<std::string> names = layout;
  for (const std::string& name : link_names(group.get()))
    if (std::find(layout.begin(), layout.end(), name) == layout.end()) names.push_back(name);
  for (const std::string& name : names) {
    if (H5Lexists(group.get(), name.c_str(), H5P_DEFAULT) <= 0) continue;
    if (auto a = stored_array(group.get(), path, name, dims)) out.arrays.push_back(std::move(*a));
  }
  if (H5Lexists(file.get(), "provenance", H5P_DEFAULT) > 0) {
    Handle provenance(H5Gopen2(file.get(), "provenance", H5P_DEFAULT), H5Gclose);
    std::vector<std::string> entries = attribute_names(provenance.get());
    for (const std::string& name : link_names(provenance.get())) entries.push_back(name);
    std::sort(entries.begin(), entries.end());
    for (const std::string& name : entries)
      if (auto value = read_provenance(path, name)) out.provenance.emplace_back(name, *value);
  }
  return out;
}

}  // namespace plenopiv::io
