// Particle lists as CSV files (x, y, z in mm): what `plenopiv simulate` reads and writes.
#include "core/sim/particle_file.hpp"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"

namespace plenopiv::sim {
namespace {

std::string trim(const std::string& s) {
  std::size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> fields;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = line.find(',', start);
    fields.push_back(trim(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start)));
    if (comma == std::string::npos) return fields;
    start = comma + 1;
  }
}

bool parse_number(const std::string& field, double& value) {
  if (field.empty()) return false;
  std::size_t used = 0;
  try {
    value = std::stod(field, &used);
  } catch (const std::exception&) {
    return false;
  }
  return used == field.size();
}

// "x", "x_mm", "x [mm]", "X (mm)": the axis letter, then nothing or a non-letter.
bool names_axis(const std::string& field, char axis) {
  return !field.empty() && std::tolower(static_cast<unsigned char>(field[0])) == axis &&
         (field.size() == 1 || !std::isalpha(static_cast<unsigned char>(field[1])));
}

}  // namespace

std::vector<Point3> read_particles_csv(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path.string() + ": cannot open the particle file");
  std::vector<Point3> particles;
  std::string line;
  int number = 0;
  bool first = true;
  while (std::getline(in, line)) {
    ++number;
    const std::string text = trim(line);
    if (text.empty() || text[0] == '#') continue;
    const std::vector<std::string> fields = split(text);
    const std::string where = path.string() + ": line " + std::to_string(number) + ": ";
    Point3 p{};
    bool numeric = true;  // every field a number: data, whatever its column count
    for (const std::string& f : fields) {
      double v;
      numeric = numeric && parse_number(f, v);
    }
    if (first && !numeric) {
      first = false;
      // A header: it must be x, y, z in that order.
      bool ok = fields.size() == 3;
      for (std::size_t k = 0; ok && k < 3; ++k) ok = names_axis(fields[k], "xyz"[k]);
      if (!ok) {
        throw InputError(where + "header '" + text + "' does not name the columns x, y, z (mm) in " +
                         "that order; write the particles as x,y,z");
      }
      continue;
    }
    first = false;
    if (fields.size() != 3) {
      throw InputError(where + "expected 3 columns x,y,z (mm), found " + std::to_string(fields.size()));
    }
    for (std::size_t k = 0; k < 3; ++k) {
      if (!parse_number(fields[k], p[k]) || !std::isfinite(p[k])) {
        throw InputError(where + "column " + std::to_string(k + 1) + " ('" + fields[k] + "') is not a finite number");
      }
    }
    particles.push_back(p);
  }
  if (in.bad()) throw InputError(path.string() + ": read error");
  if (particles.empty()) throw InputError(path.string() + ": no particles (expected lines x,y,z in mm)");
  return particles;
}

void write_particles_csv(const std::filesystem::path& path, std::span<const Point3> particles) {
  io::write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (!f) throw InputError(path.string() + ": cannot write the particle file");
    std::fprintf(f, "x_mm,y_mm,z_mm\n");
    for (const Point3& p : particles) std::fprintf(f, "%.17g,%.17g,%.17g\n", p[0], p[1], p[2]);
    const bool failed = std::ferror(f) != 0;
    if (std::fclose(f) != 0 || failed) throw InputError(path.string() + ": write error");
  });
}

}  // namespace plenopiv::sim
