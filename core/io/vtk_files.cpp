// VTK XML image data (.vti) for ParaView: volumes as a scalar, vector fields as vectors.
#include "core/io/vtk_files.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"

namespace plenopiv::io {
namespace {

// One point-data array: raw little-endian bytes in the appended section.
struct Array {
  std::string name;
  std::string type;  // Float32, UInt8
  int components;
  std::vector<char> bytes;
};

template <typename Values>
Array make_array(const std::string& name, const std::string& type, int components, const Values& values) {
  Array a{name, type, components, {}};
  a.bytes.resize(values.size() * sizeof(values[0]));
  std::memcpy(a.bytes.data(), values.data(), a.bytes.size());
  return a;
}

std::vector<float> interleave(const std::vector<float>& x, const std::vector<float>& y, const std::vector<float>& z,
                              double scale) {
  std::vector<float> out(3 * x.size());
  for (std::size_t i = 0; i < x.size(); ++i) {
    out[3 * i] = float(x[i] * scale);
    out[3 * i + 1] = float(y[i] * scale);
    out[3 * i + 2] = float(z[i] * scale);
  }
  return out;
}

// Writes <VTKFile type="ImageData"> with raw appended data (UInt64 byte-count headers), the
// compact binary form ParaView reads directly. VTK's point order is x fastest, as ours.
void write_image_data(const std::filesystem::path& path, const Grid3& g, const std::vector<Array>& arrays) {
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw InputError(path.string() + ": cannot create file");
    std::ostringstream head;
    head.precision(17);
    head << "<?xml version=\"1.0\"?>\n"
         << "<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" "
            "header_type=\"UInt64\">\n"
         << "  <ImageData WholeExtent=\"0 " << g.shape[0] - 1 << " 0 " << g.shape[1] - 1 << " 0 " << g.shape[2] - 1
         << "\" Origin=\"" << g.origin_mm[0] << " " << g.origin_mm[1] << " " << g.origin_mm[2] << "\" Spacing=\""
         << g.spacing_mm[0] << " " << g.spacing_mm[1] << " " << g.spacing_mm[2] << "\">\n"
         << "    <Piece Extent=\"0 " << g.shape[0] - 1 << " 0 " << g.shape[1] - 1 << " 0 " << g.shape[2] - 1 << "\">\n"
         << "      <PointData>\n";
    std::uint64_t offset = 0;
    for (const Array& a : arrays) {
      head << "        <DataArray type=\"" << a.type << "\" Name=\"" << a.name << "\" NumberOfComponents=\""
           << a.components << "\" format=\"appended\" offset=\"" << offset << "\"/>\n";
      offset += sizeof(std::uint64_t) + a.bytes.size();
    }
    head << "      </PointData>\n    </Piece>\n  </ImageData>\n"
         << "  <AppendedData encoding=\"raw\">\n   _";
    out << head.str();
    for (const Array& a : arrays) {
      const std::uint64_t n = a.bytes.size();
      out.write(reinterpret_cast<const char*>(&n), sizeof n);
      out.write(a.bytes.data(), std::streamsize(a.bytes.size()));
    }
    out << "\n  </AppendedData>\n</VTKFile>\n";
    out.close();
    if (!out) throw InputError(path.string() + ": write failed (disk full?)");
  });
}

}  // namespace

void write_volume_vti(const std::filesystem::path& path, const Volume& volume) {
  if (volume.data.size() != volume.grid.count() || volume.grid.count() == 0) {
    throw InputError(path.string() + ": volume array does not match its grid");
  }
  write_image_data(path, volume.grid, {make_array("intensity", "Float32", 1, volume.data)});
}

void write_vector_field_vti(const std::filesystem::path& path, const VectorField& f,
                            const std::vector<NamedField>& extra) {
  const std::size_t n = f.grid.count();
  if (n == 0 || f.dx_mm.size() != n || f.dy_mm.size() != n || f.dz_mm.size() != n || f.valid.size() != n ||
      f.peak_ratio.size() != n) {
    throw InputError(path.string() + ": vector field arrays do not match its grid");
  }
  if (!(f.dt_s > 0)) throw InputError(path.string() + ": dt_s must be > 0 to give velocities");
  std::vector<Array> arrays;
  arrays.push_back(make_array("displacement_mm", "Float32", 3, interleave(f.dx_mm, f.dy_mm, f.dz_mm, 1.0)));
  arrays.push_back(make_array("velocity_m_s", "Float32", 3, interleave(f.dx_mm, f.dy_mm, f.dz_mm, 1e-3 / f.dt_s)));
  arrays.push_back(make_array("valid", "UInt8", 1, f.valid));
  arrays.push_back(make_array("peak_ratio", "Float32", 1, f.peak_ratio));
  if (!f.sigma_dx_mm.empty() || !f.sigma_dy_mm.empty() || !f.sigma_dz_mm.empty()) {
    if (f.sigma_dx_mm.size() != n || f.sigma_dy_mm.size() != n || f.sigma_dz_mm.size() != n)
      throw InputError(path.string() + ": the vector field's sigma arrays do not match its grid");
    arrays.push_back(make_array("sigma_velocity_m_s", "Float32", 3,
                                interleave(f.sigma_dx_mm, f.sigma_dy_mm, f.sigma_dz_mm, 1e-3 / f.dt_s)));
  }
  for (const NamedField& e : extra) {
    const bool vec = e.name.size() > 4 && e.name.substr(e.name.size() - 4) == "_vec";
    if (e.values.size() != (vec ? 3 : 1) * n) {
      throw InputError(path.string() + ": field " + e.name + " does not match the grid");
    }
    arrays.push_back(make_array(e.name, "Float32", vec ? 3 : 1, e.values));
  }
  write_image_data(path, f.grid, arrays);
}

void write_vtk_series(const std::filesystem::path& path, const std::vector<SeriesEntry>& entries) {
  std::ostringstream xml;
  xml.precision(17);
  xml << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
         "  <Collection>\n";
  for (const SeriesEntry& e : entries) {
    if (e.file.find_first_of("\"<>&") != std::string::npos) {
      throw InputError(path.string() + ": series entry '" + e.file + "' is not a plain file name");
    }
    if (!std::isfinite(e.time_s)) throw InputError(path.string() + ": series entry " + e.file + " has no time");
    xml << "    <DataSet timestep=\"" << e.time_s << "\" group=\"\" part=\"0\" file=\"" << e.file << "\"/>\n";
  }
  xml << "  </Collection>\n</VTKFile>\n";
  const std::string text = xml.str();
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw std::runtime_error(path.string() + ": cannot write");
  });
}

}  // namespace plenopiv::io
