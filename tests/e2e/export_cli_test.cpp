// `plenopiv export`: a vector field file (with vorticity, flags, provenance and an array the
// layout does not name) and a volume file to Tecplot, .npz, CSV and NetCDF, each read back by
// Debian's Python (numpy, netCDF4, csv) and compared with the HDF5 (h5py): values, coordinates,
// units; bad input refused by name with nothing written.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/io/hdf5_files.hpp"
#include "core/piv/peak_fit.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

namespace fs = std::filesystem;
using testing_support::binary;
using testing_support::run_command;

fs::path scratch() { return testing_support::temp_dir("export"); }

// A 5 x 4 x 3 field with invalid nodes (NaN vorticity), flag bits and per-vector sigma_u.
fs::path write_field_file(const fs::path& path) {
  Grid3 g;
  g.shape = {5, 4, 3};
  g.origin_mm = {-1.0, -0.75, 0.25};
  g.spacing_mm = {0.5, 0.25, 0.125};
  VectorField f(g);
  f.dt_s = 40e-6;
  std::vector<float> vorticity(g.count()), sigma(g.count());
  std::vector<std::uint8_t> flags(g.count(), 0);
  for (std::size_t n = 0; n < g.count(); ++n) {
    f.dx_mm[n] = 0.01f * float(n) - 0.1f;
    f.dy_mm[n] = 0.003f * float(n % 7);
    f.dz_mm[n] = -0.002f * float(n % 5);
    f.valid[n] = n % 11 != 3;
    f.peak_ratio[n] = 1.5f + 0.1f * float(n % 4);
    vorticity[n] = f.valid[n] ? 123.25f * float(n % 9) - 400.f : NAN;
    sigma[n] = 0.001f * float(n % 3);
    if (n % 13 == 2) flags[n] = piv::flag_second_peak;
  }
  io::write_vector_field_h5(path, f, {{"vorticity_z", vorticity, "1/s"}, {"sigma_u", sigma, "m/s"}},
                            {{"settings", "passes: 32@50\n"}, {"dt_source", "nominal"}},
                            io::FlagField{"flags", flags, piv::kVectorFlagLegend});
  return path;
}

int plenopiv(const std::vector<std::string>& args, std::string& out) {
  std::vector<std::string> argv{binary("plenopiv")};
  argv.insert(argv.end(), args.begin(), args.end());
  return run_command(argv, out);
}

// Reads every export back and compares it with the HDF5 file, array by array.
constexpr const char* kCheckScript = R"PY(
import csv, shlex, sys
import h5py, netCDF4, numpy as np

h5, npz_path, csv_path, nc_path, dat_path, group = sys.argv[1:7]
f = h5py.File(h5, 'r')
g = f[group] if group != '/' else f

def text(v):
    return v.decode() if isinstance(v, bytes) else str(v)

names = [n for n in g if isinstance(g[n], h5py.Dataset) and g[n].ndim == 3]
units = {n: text(g[n].attrs['units']) for n in names}
shape = g[names[0]].shape
coords = {a: g[a][...] for a in 'xyz'}
Z, Y, X = np.meshgrid(coords['z'], coords['y'], coords['x'], indexing='ij')
node = {'x': X.ravel(), 'y': Y.ravel(), 'z': Z.ravel()}

def same(a, b):
    a = np.asarray(a, dtype=np.float64); b = np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)

# NumPy .npz: arrays named and typed as in HDF5, coordinates, names/units, dt_s
z = np.load(npz_path, allow_pickle=False)
npz_units = dict(zip(z['names'].tolist(), z['units'].tolist()))
for n in names:
    assert z[n].dtype == g[n].dtype and z[n].shape == shape, (n, z[n].dtype, g[n].dtype)
    assert same(z[n], g[n][...]), n
    assert npz_units[n] == units[n], (n, npz_units[n], units[n])
for a in 'xyz':
    assert same(z[a], coords[a]) and npz_units[a] == 'mm', a
if group == 'vectors':
    assert float(z['dt_s']) == float(g.attrs['dt_s'][0])

# NetCDF-4: dimensions z, y, x, coordinate variables, units, long_name, the flags legend
d = netCDF4.Dataset(nc_path)
d.set_auto_mask(False)
assert d.Conventions.startswith('CF-')
for n in names:
    v = d[n]
    assert v.dimensions == ('z', 'y', 'x'), (n, v.dimensions)
    assert same(v[...], g[n][...]), n
    assert v.units == units[n], (n, v.units, units[n])
    assert v.long_name
for a in 'xyz':
    assert same(d[a][...], coords[a]) and d[a].units == 'mm' and d[a].axis == a.upper(), a
if group == 'vectors':
    assert d['flags'].legend == text(g['flags'].attrs['legend'])
    assert d.dt_s == float(g.attrs['dt_s'][0])
    assert d.provenance_settings == 'passes: 32@50\n', d.provenance_settings

# CSV: one row per node, x fastest, header "name (units)"
with open(csv_path, newline='') as fh:
    rows = list(csv.reader(fh))
header = rows[0]
assert header[:3] == ['x (mm)', 'y (mm)', 'z (mm)'], header
assert sorted(header[3:]) == sorted('%s (%s)' % (n, units[n]) for n in names), (header, names)
data = np.array(rows[1:], dtype=np.float64)
assert data.shape == (np.prod(shape), len(header)), data.shape
for i, a in enumerate('xyz'):
    assert same(data[:, i], node[a]), a
for n in names:
    # float32 values are written in the shortest text that reads back as the same float32
    column = data[:, header.index('%s (%s)' % (n, units[n]))].astype(np.float32)
    assert same(column, g[n][...].ravel().astype(np.float32)), n

# Tecplot ASCII: VARIABLES with units, an ordered POINT zone, NaN as the declared missing value
lines = open(dat_path).read().splitlines()
variables = shlex.split(lines[1].split('=', 1)[1])
assert variables[:3] == ['x [mm]', 'y [mm]', 'z [mm]'], variables
assert sorted(variables[3:]) == sorted('%s [%s]' % (n, units[n]) for n in names), variables
aux = {l.split()[1]: shlex.split(l.split('=', 1)[1])[0] for l in lines if l.startswith('DATASETAUXDATA')}
missing = float(aux['missing_value'])
zone = next(i for i, l in enumerate(lines) if l.startswith('ZONE'))
assert 'I=%d, J=%d, K=%d, DATAPACKING=POINT' % (shape[2], shape[1], shape[0]) in lines[zone], lines[zone]
values = np.array([l.split() for l in lines[zone + 1:]], dtype=np.float64)
values[values == missing] = np.nan
for i, a in enumerate('xyz'):
    assert same(values[:, i], node[a]), a
for n in names:
    column = values[:, variables.index('%s [%s]' % (n, units[n]))].astype(np.float32)
    assert same(column, g[n][...].ravel().astype(np.float32)), n
print('exports ok:', len(names), 'arrays')
)PY";

void export_all_and_check(const fs::path& h5, const std::string& group, const std::vector<std::string>& must_hold) {
  const fs::path dir = h5.parent_path(), stem = dir / h5.stem();
  std::string out;
  for (const auto& [format, ext] : std::vector<std::pair<std::string, std::string>>{
           {"npz", ".npz"}, {"csv", ".csv"}, {"netcdf", ".nc"}, {"tecplot", ".dat"}}) {
    ASSERT_EQ(plenopiv({"export", h5.string(), "--to", format}, out), 0) << out;
    EXPECT_NE(out.find(stem.string() + ext), std::string::npos) << out;
    EXPECT_TRUE(fs::exists(stem.string() + ext)) << format;
  }
  const fs::path script = dir / "check_exports.py";
  std::ofstream(script) << kCheckScript;
  ASSERT_TRUE(fs::exists("/usr/bin/python3")) << "Debian's python3 (scripts/setup.sh) is needed";
  const int rc = run_command({"/usr/bin/python3", script.string(), h5.string(), stem.string() + ".npz",
                              stem.string() + ".csv", stem.string() + ".nc", stem.string() + ".dat", group},
                             out);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("exports ok"), std::string::npos) << out;
  // The arrays the file holds go over, whatever their names (sigma_u is not in the layout).
  std::ifstream csv(stem.string() + ".csv");
  std::string header;
  std::getline(csv, header);
  for (const std::string& name : must_hold) EXPECT_NE(header.find(name), std::string::npos) << header;
}

TEST(ExportCli, VectorFieldToEveryFormatReadsBackAsTheHdf5) {
  const fs::path h5 = write_field_file(scratch() / "field.h5");
  export_all_and_check(h5, "vectors",
                       {"dx (mm)", "u (m/s)", "valid (1)", "vorticity_z (1/s)", "sigma_u (m/s)", "flags (1)"});
}

TEST(ExportCli, VolumeToEveryFormatReadsBackAsTheHdf5) {
  Grid3 g;
  g.shape = {6, 5, 4};
  g.origin_mm = {-2.5, -2.0, -1.5};
  g.spacing_mm = {1.0, 1.0, 1.0};
  Volume v(g);
  for (std::size_t n = 0; n < v.data.size(); ++n) v.data[n] = 0.5f * float(n % 17);
  const fs::path h5 = scratch() / "volume.h5";
  io::write_volume_h5(h5, v, {{"settings", "iterations: 5\n"}});
  export_all_and_check(h5, "/", {"volume (arbitrary (reconstructed intensity))"});
}

TEST(ExportCli, GivenOutputNameIsUsed) {
  const fs::path h5 = write_field_file(scratch() / "named.h5");
  std::string out;
  ASSERT_EQ(plenopiv({"export", h5.string(), "--to", "netcdf", "-o", (scratch() / "other.nc").string()}, out), 0)
      << out;
  EXPECT_TRUE(fs::exists(scratch() / "other.nc"));
  EXPECT_FALSE(fs::exists(scratch() / "named.nc"));
}

TEST(ExportCli, BadInputIsRefusedByName) {
  const fs::path dir = scratch() / "bad";
  fs::create_directories(dir);
  const fs::path h5 = write_field_file(dir / "field.h5");
  std::string out;
  EXPECT_EQ(plenopiv({"export", (dir / "missing.h5").string(), "--to", "csv"}, out), 2);
  EXPECT_NE(out.find("missing.h5: no such file"), std::string::npos) << out;

  std::ofstream(dir / "notes.h5") << "not an HDF5 file";
  EXPECT_EQ(plenopiv({"export", (dir / "notes.h5").string(), "--to", "npz"}, out), 2);
  EXPECT_NE(out.find("notes.h5: not an HDF5 file"), std::string::npos) << out;

  // HDF5, but neither a vector field nor a volume: a calibration-like file with other datasets.
  EXPECT_EQ(run_command({"/usr/bin/python3", "-c",
                         "import h5py, sys; h = h5py.File(sys.argv[1], 'w'); h['lenses'] = [1.0, 2.0]",
                         (dir / "lenses.h5").string()},
                        out),
            0)
      << out;
  EXPECT_EQ(plenopiv({"export", (dir / "lenses.h5").string(), "--to", "netcdf"}, out), 2);
  EXPECT_NE(out.find("lenses.h5: neither /vectors nor /volume (not a plenopiv vector field or volume file)"),
            std::string::npos)
      << out;

  EXPECT_EQ(plenopiv({"export", h5.string(), "--to", "vtk"}, out), 2);
  EXPECT_NE(out.find("unknown export format 'vtk': give tecplot, npz, csv or netcdf"), std::string::npos) << out;

  EXPECT_EQ(plenopiv({"export", h5.string(), "--to", "csv", "-o", (dir / "no-such-folder" / "f.csv").string()}, out),
            2);
  EXPECT_NE(out.find("no-such-folder does not exist"), std::string::npos) << out;

  EXPECT_NE(plenopiv({"export", h5.string()}, out), 0);
  EXPECT_NE(out.find("--to"), std::string::npos) << out;

  for (const char* ext : {".csv", ".npz", ".nc", ".dat"}) EXPECT_FALSE(fs::exists(dir / (std::string("field") + ext)));
  EXPECT_FALSE(fs::exists(dir / "notes.npz"));
  EXPECT_FALSE(fs::exists(dir / "lenses.nc"));
}

}  // namespace
}  // namespace plenopiv
