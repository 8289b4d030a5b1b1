// VTK XML image data (.vti) for ParaView: volumes as a scalar, vector fields as vectors.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/base/grid.hpp"
#include "core/io/hdf5_files.hpp"

namespace plenopiv::io {

// Point data "intensity" on the volume's grid (origin and spacing in mm). Written atomically.
void write_volume_vti(const std::filesystem::path& path, const Volume& volume);
// Point data "displacement_mm" (3 components), "velocity_m_s" (needs dt_s > 0), "valid",
// "peak_ratio" (NaN where no second peak was searched), "sigma_velocity_m_s" (3 components: the standard uncertainty of
// u, v, w; NaN where there is none; when the field has its sigma), and each extra field (1 component, or 3 when its
// name ends in "_vec"). Atomic.
void write_vector_field_vti(const std::filesystem::path& path, const VectorField& field,
                            const std::vector<NamedField>& extra = {});

// One file of a time series: its time (s) and its name relative to the series file.
struct SeriesEntry {
  double time_s = 0;
  std::string file;
};
// A ParaView collection (.pvd) listing `entries` as time steps: ParaView opens the series as one
// animated data set. Written atomically.
void write_vtk_series(const std::filesystem::path& path, const std::vector<SeriesEntry>& entries);

}  // namespace plenopiv::io
