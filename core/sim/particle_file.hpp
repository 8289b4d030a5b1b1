// Particle lists as CSV files (x, y, z in mm): what `plenopiv simulate` reads and writes.
#pragma once

#include <filesystem>
#include <span>
#include <vector>

#include "core/sim/particles.hpp"

namespace plenopiv::sim {

// Reads one particle per line: three comma-separated numbers x, y, z in mm. Empty lines and
// lines starting with '#' are skipped. An optional first line may name the columns; it must
// name x, y, z in that order ("x", "x_mm", "x [mm]", "X (mm)"...), so a file with its columns
// in another order or with extra columns is refused rather than silently misread.
// Throws InputError naming the file, the line and the reason (unreadable file, wrong column
// count, a field that is not a finite number, no particles).
std::vector<Point3> read_particles_csv(const std::filesystem::path& path);
// Writes "x_mm,y_mm,z_mm" and one line per particle (17 significant digits), atomically.
void write_particles_csv(const std::filesystem::path& path, std::span<const Point3> particles);

}  // namespace plenopiv::sim
