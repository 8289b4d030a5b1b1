// Exports of a vector field or volume file to the formats other tools read: Tecplot ASCII, NumPy
// .npz (libzip), CSV and NetCDF-4 (libnetcdf).
#include "core/io/export_files.hpp"

#include <netcdf.h>
#include <zip.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <vector>

#include "core/base/build_info.hpp"
#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"

namespace plenopiv::io {
namespace {

// The node coordinates of axis `a` (0: x, 1: y, 2: z), mm.
std::vector<double> axis_of(const Grid3& g, int a) {
  std::vector<double> axis(std::size_t(g.shape[a]));
  for (int i = 0; i < g.shape[a]; ++i) axis[std::size_t(i)] = g.coordinate_mm(a, i);
  return axis;
}

const char* const kAxisNames[3] = {"x", "y", "z"};

std::string units_or_one(const StoredArray& a) { return a.units.empty() ? "1" : a.units; }

// Text output through a large buffer; to_chars writes the shortest text that reads back as the
// same float (or double).
class TextWriter {
 public:
  explicit TextWriter(const std::filesystem::path& path) : file_(std::fopen(path.c_str(), "wb")), path_(path) {
    if (!file_) throw std::runtime_error(path.string() + ": cannot create");
    std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
  }
  ~TextWriter() {
    if (file_) std::fclose(file_);
  }
  TextWriter(const TextWriter&) = delete;
  TextWriter& operator=(const TextWriter&) = delete;
  void text(const std::string& s) { std::fwrite(s.data(), 1, s.size(), file_); }
  void character(char c) { std::fputc(c, file_); }
  template <typename T>
  void number(T value) {
    char buffer[64];
    const auto end = std::to_chars(buffer, buffer + sizeof buffer, value).ptr;
    std::fwrite(buffer, 1, std::size_t(end - buffer), file_);
  }
  void close() {
    const bool failed = std::ferror(file_) != 0;
    const int closed = std::fclose(file_);
    file_ = nullptr;
    if (failed || closed != 0) throw std::runtime_error(path_.string() + ": write failed");
  }

 private:
  std::FILE* file_;
  std::filesystem::path path_;
};

// Calls `per_node(n, i, j, k)` for every node, x fastest (the arrays' own order).
template <typename F>
void for_each_node(const Grid3& g, F per_node) {
  std::size_t n = 0;
  for (int k = 0; k < g.shape[2]; ++k)
    for (int j = 0; j < g.shape[1]; ++j)
      for (int i = 0; i < g.shape[0]; ++i) per_node(n++, i, j, k);
}

// Writes a node's value: uint8 arrays as whole numbers, floats in their shortest exact form.
void write_value(TextWriter& w, const StoredArray& a, std::size_t n) {
  if (a.is_uint8) {
    w.number(int(a.values[n]));
  } else {
    w.number(a.values[n]);
  }
}

// ---- Tecplot ASCII ----

// Tecplot has no NaN: nodes without a value get this, declared in the file as missing_value.
constexpr float kTecplotMissing = -1e30f;

std::string tecplot_quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) out += c == '"' ? '\'' : c;
  return out + "\"";
}

void write_tecplot(const StoredFields& f, const std::filesystem::path& tmp, const std::filesystem::path& source) {
  TextWriter w(tmp);
  w.text("TITLE = " + tecplot_quoted("plenopiv " + f.kind + " from " + source.filename().string()) + "\n");
  w.text("VARIABLES = \"x [mm]\" \"y [mm]\" \"z [mm]\"");
  for (const StoredArray& a : f.arrays) w.text(" " + tecplot_quoted(a.name + " [" + units_or_one(a) + "]"));
  w.text("\n");
  if (f.dt_s) {
    w.text("DATASETAUXDATA dt_s = \"");
    w.number(*f.dt_s);
    w.text("\"\n");
  }
  w.text("DATASETAUXDATA missing_value = \"");
  w.number(kTecplotMissing);
  w.text("\"\n");
  w.text("DATASETAUXDATA source = " + tecplot_quoted(source.string()) + "\n");
  const Grid3& g = f.grid;
  w.text("ZONE T=" + tecplot_quoted(f.kind) + ", I=" + std::to_string(g.shape[0]) +
         ", J=" + std::to_string(g.shape[1]) + ", K=" + std::to_string(g.shape[2]) + ", DATAPACKING=POINT\n");
  for_each_node(g, [&](std::size_t n, int i, int j, int k) {
    w.number(g.coordinate_mm(0, i));
    w.character(' ');
    w.number(g.coordinate_mm(1, j));
    w.character(' ');
    w.number(g.coordinate_mm(2, k));
    for (const StoredArray& a : f.arrays) {
      w.character(' ');
      if (!a.is_uint8 && !std::isfinite(a.values[n])) {
        w.number(kTecplotMissing);
      } else {
        write_value(w, a, n);
      }
    }
    w.character('\n');
  });
  w.close();
}

// ---- CSV ----

// A CSV field, quoted (RFC 4180) when it holds a comma, quote or line break.
std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

void write_csv(const StoredFields& f, const std::filesystem::path& tmp) {
  TextWriter w(tmp);
  w.text("x (mm),y (mm),z (mm)");
  for (const StoredArray& a : f.arrays) w.text("," + csv_field(a.name + " (" + units_or_one(a) + ")"));
  w.text("\n");
  const Grid3& g = f.grid;
  for_each_node(g, [&](std::size_t n, int i, int j, int k) {
    w.number(g.coordinate_mm(0, i));
    w.character(',');
    w.number(g.coordinate_mm(1, j));
    w.character(',');
    w.number(g.coordinate_mm(2, k));
    for (const StoredArray& a : f.arrays) {
      w.character(',');
      write_value(w, a, n);
    }
    w.character('\n');
  });
  w.close();
}

// ---- NumPy .npz: a zip archive of .npy files ----

// A .npy file (format version 1.0): magic, header length, a Python dict literal padded with
// spaces to a multiple of 64 bytes, then the data in C order.
std::string npy(const std::string& descr, const std::vector<std::size_t>& shape, const void* data, std::size_t bytes) {
  std::string dims = "(";
  for (std::size_t d : shape) dims += std::to_string(d) + ", ";
  if (shape.size() > 1) dims.resize(dims.size() - 2);
  if (shape.size() == 1) dims.resize(dims.size() - 1);
  dims += ")";
  std::string header = "{'descr': '" + descr + "', 'fortran_order': False, 'shape': " + dims + ", }";
  const std::size_t preamble = 10;
  header.append(63 - (preamble + header.size()) % 64, ' ');
  header += '\n';
  if (header.size() > 65535) throw std::runtime_error(".npy header too long");
  std::string out = "\x93NUMPY";
  out += char(1);
  out += char(0);
  out += char(header.size() & 0xff);
  out += char(header.size() >> 8);
  out += header;
  out.append(static_cast<const char*>(data), bytes);
  return out;
}

// UTF-8 to the UCS-4 code points of a NumPy unicode string ('<U'); a malformed byte reads as
// U+FFFD.
std::vector<std::uint32_t> code_points(const std::string& s) {
  std::vector<std::uint32_t> out;
  for (std::size_t i = 0; i < s.size();) {
    const auto c = static_cast<unsigned char>(s[i]);
    const int extra = c < 0x80 ? 0 : (c >> 5) == 6 ? 1 : (c >> 4) == 14 ? 2 : (c >> 3) == 30 ? 3 : -1;
    const bool complete = extra >= 0 && i + std::size_t(extra) < s.size();
    if (!complete) {
      out.push_back(0xFFFD);
      ++i;
      continue;
    }
    std::uint32_t cp = extra == 0 ? c : c & (0x3F >> extra);
    for (int e = 1; e <= extra; ++e) cp = cp << 6 | (static_cast<unsigned char>(s[i + std::size_t(e)]) & 0x3F);
    out.push_back(cp);
    i += std::size_t(extra) + 1;
  }
  return out;
}

std::string npy_strings(const std::vector<std::string>& strings) {
  std::vector<std::vector<std::uint32_t>> points;
  std::size_t width = 1;
  for (const auto& s : strings) {
    points.push_back(code_points(s));
    width = std::max(width, points.back().size());
  }
  std::vector<std::uint32_t> data(width * strings.size(), 0);  // little-endian on this machine
  for (std::size_t i = 0; i < points.size(); ++i) std::copy(points[i].begin(), points[i].end(), &data[i * width]);
  return npy("<U" + std::to_string(width), {strings.size()}, data.data(), data.size() * 4);
}

void write_npz(const StoredFields& f, const std::filesystem::path& tmp, const std::filesystem::path& path) {
  static_assert(std::endian::native == std::endian::little, ".npy data is written as '<' (little-endian)");
  std::vector<std::pair<std::string, std::string>> members;  // name, .npy bytes
  std::vector<std::string> names, units;
  for (int a = 0; a < 3; ++a) {
    const auto axis = axis_of(f.grid, a);
    members.emplace_back(kAxisNames[a], npy("<f8", {axis.size()}, axis.data(), axis.size() * sizeof(double)));
    names.emplace_back(kAxisNames[a]);
    units.emplace_back("mm");
  }
  const std::vector<std::size_t> shape = {std::size_t(f.grid.shape[2]), std::size_t(f.grid.shape[1]),
                                          std::size_t(f.grid.shape[0])};
  for (const StoredArray& a : f.arrays) {
    if (a.is_uint8) {
      std::vector<std::uint8_t> bytes(a.values.size());
      std::transform(a.values.begin(), a.values.end(), bytes.begin(), [](float v) { return std::uint8_t(v); });
      members.emplace_back(a.name, npy("|u1", shape, bytes.data(), bytes.size()));
    } else {
      members.emplace_back(a.name, npy("<f4", shape, a.values.data(), a.values.size() * sizeof(float)));
    }
    names.push_back(a.name);
    units.push_back(units_or_one(a));
  }
  if (f.dt_s) {
    members.emplace_back("dt_s", npy("<f8", {}, &*f.dt_s, sizeof(double)));
    names.emplace_back("dt_s");
    units.emplace_back("s");
  }
  members.emplace_back("names", npy_strings(names));
  members.emplace_back("units", npy_strings(units));

  int error = 0;
  zip_t* archive = zip_open(tmp.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &error);
  if (!archive) {
    zip_error_t e;
    zip_error_init_with_code(&e, error);
    const std::string why = zip_error_strerror(&e);
    zip_error_fini(&e);
    throw std::runtime_error(path.string() + ": cannot create the zip archive: " + why);
  }
  // The buffers stay alive in `members` until zip_close reads them.
  for (const auto& [name, bytes] : members) {
    zip_source_t* source = zip_source_buffer(archive, bytes.data(), bytes.size(), 0);
    if (!source || zip_file_add(archive, (name + ".npy").c_str(), source, ZIP_FL_OVERWRITE | ZIP_FL_ENC_UTF_8) < 0) {
      if (source) zip_source_free(source);
      const std::string why = zip_strerror(archive);
      zip_discard(archive);
      throw std::runtime_error(path.string() + ": cannot add " + name + ".npy: " + why);
    }
  }
  if (zip_close(archive) != 0) {
    const std::string why = zip_strerror(archive);
    zip_discard(archive);
    throw std::runtime_error(path.string() + ": cannot write the zip archive: " + why);
  }
}

// ---- NetCDF-4 ----

class NetcdfFile {
 public:
  NetcdfFile(const std::filesystem::path& tmp, const std::filesystem::path& path) : path_(path) {
    check(nc_create(tmp.c_str(), NC_NETCDF4 | NC_CLOBBER, &id_), "create");
  }
  ~NetcdfFile() {
    if (id_ >= 0) nc_close(id_);
  }
  NetcdfFile(const NetcdfFile&) = delete;
  NetcdfFile& operator=(const NetcdfFile&) = delete;
  int id() const { return id_; }
  void check(int status, const std::string& what) const {
    if (status != NC_NOERR)
      throw std::runtime_error(path_.string() + ": NetCDF: cannot " + what + ": " + nc_strerror(status));
  }
  void text(int var, const std::string& name, const std::string& value) const {
    check(nc_put_att_text(id_, var, name.c_str(), value.size(), value.data()), "write attribute " + name);
  }
  void close() {
    const int status = nc_close(id_);
    id_ = -1;
    check(status, "write");
  }

 private:
  int id_ = -1;
  std::filesystem::path path_;
};

const char* const kAxisLongNames[3] = {"x, right on the sensor", "y, down on the sensor",
                                       "z, away from the camera (0: the nominal focal plane)"};

// A NetCDF name: letters, digits and _ (other characters become _).
std::string netcdf_name(const std::string& s) {
  std::string out = s;
  for (char& c : out)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') c = '_';
  return out;
}

void write_netcdf(const StoredFields& f, const std::filesystem::path& tmp, const std::filesystem::path& path,
                  const std::filesystem::path& source) {
  NetcdfFile nc(tmp, path);
  int dims[3];  // z, y, x
  for (int a = 0; a < 3; ++a)
    nc.check(nc_def_dim(nc.id(), kAxisNames[a], std::size_t(f.grid.shape[a]), &dims[2 - a]),
             std::string("define dimension ") + kAxisNames[a]);
  int axis_vars[3];
  for (int a = 0; a < 3; ++a) {
    nc.check(nc_def_var(nc.id(), kAxisNames[a], NC_DOUBLE, 1, &dims[2 - a], &axis_vars[a]),
             std::string("define ") + kAxisNames[a]);
    nc.text(axis_vars[a], "units", "mm");
    nc.text(axis_vars[a], "long_name", kAxisLongNames[a]);
    nc.text(axis_vars[a], "axis", std::string(1, char('X' + a)));
  }
  std::vector<int> vars;
  for (const StoredArray& a : f.arrays) {
    int var = -1;
    nc.check(nc_def_var(nc.id(), netcdf_name(a.name).c_str(), a.is_uint8 ? NC_UBYTE : NC_FLOAT, 3, dims, &var),
             "define " + a.name);
    nc.check(nc_def_var_deflate(nc.id(), var, 1, 1, 1), "compress " + a.name);
    nc.text(var, "units", units_or_one(a));
    nc.text(var, "long_name", a.long_name.empty() ? a.name : a.long_name);
    if (!a.legend.empty()) nc.text(var, "legend", a.legend);
    vars.push_back(var);
  }
  nc.text(NC_GLOBAL, "Conventions", "CF-1.8");
  nc.text(NC_GLOBAL, "title", "plenopiv " + f.kind);
  nc.text(NC_GLOBAL, "source", source.string());
  nc.text(NC_GLOBAL, "history", "exported by plenopiv " + std::string(build_version()) + " (plenopiv export)");
  if (f.dt_s) nc.check(nc_put_att_double(nc.id(), NC_GLOBAL, "dt_s", NC_DOUBLE, 1, &*f.dt_s), "write dt_s");
  for (const auto& [name, value] : f.provenance) nc.text(NC_GLOBAL, "provenance_" + netcdf_name(name), value);
  nc.check(nc_enddef(nc.id()), "define the variables");
  for (int a = 0; a < 3; ++a) {
    const auto axis = axis_of(f.grid, a);
    nc.check(nc_put_var_double(nc.id(), axis_vars[a], axis.data()), std::string("write ") + kAxisNames[a]);
  }
  for (std::size_t i = 0; i < f.arrays.size(); ++i) {
    const StoredArray& a = f.arrays[i];
    if (a.is_uint8) {
      std::vector<unsigned char> bytes(a.values.size());
      std::transform(a.values.begin(), a.values.end(), bytes.begin(),
                     [](float v) { return static_cast<unsigned char>(v); });
      nc.check(nc_put_var_uchar(nc.id(), vars[i], bytes.data()), "write " + a.name);
    } else {
      nc.check(nc_put_var_float(nc.id(), vars[i], a.values.data()), "write " + a.name);
    }
  }
  nc.close();
}

}  // namespace

ExportFormat export_format_from(const std::string& name) {
  if (name == "tecplot") return ExportFormat::tecplot;
  if (name == "npz") return ExportFormat::npz;
  if (name == "csv") return ExportFormat::csv;
  if (name == "netcdf") return ExportFormat::netcdf;
  throw InputError("unknown export format '" + name + "': give tecplot, npz, csv or netcdf");
}

std::string export_extension(ExportFormat format) {
  switch (format) {
    case ExportFormat::tecplot:
      return ".dat";
    case ExportFormat::npz:
      return ".npz";
    case ExportFormat::csv:
      return ".csv";
    case ExportFormat::netcdf:
      return ".nc";
  }
  return "";
}

void export_fields(const StoredFields& fields, ExportFormat format, const std::filesystem::path& out,
                   const std::filesystem::path& source) {
  const auto folder = out.parent_path().empty() ? std::filesystem::path(".") : out.parent_path();
  if (!std::filesystem::is_directory(folder))
    throw InputError(out.string() + ": folder " + folder.string() + " does not exist");
  for (const StoredArray& a : fields.arrays)
    if (a.values.size() != fields.grid.count())
      throw InputError(source.string() + ": " + a.name + " does not match the grid");
  write_atomically(out, [&](const std::filesystem::path& tmp) {
    switch (format) {
      case ExportFormat::tecplot:
        return write_tecplot(fields, tmp, source);
      case ExportFormat::npz:
        return write_npz(fields, tmp, out);
      case ExportFormat::csv:
        return write_csv(fields, tmp);
      case ExportFormat::netcdf:
        return write_netcdf(fields, tmp, out, source);
    }
  });
}

}  // namespace plenopiv::io
