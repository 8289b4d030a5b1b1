// `plenopiv export FILE --to tecplot|npz|csv|netcdf [-o OUT]`: a vector field or volume file
// (HDF5) to the formats other tools read, every array with its coordinates and units (core/io).
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include "clients/cli/commands.hpp"
#include "core/base/errors.hpp"
#include "core/io/export_files.hpp"
#include "core/io/hdf5_files.hpp"

namespace plenopiv::client {
namespace {

struct ExportOptions {
  std::string input, format, output;
};

void run_export(const ExportOptions& o) {
  const io::ExportFormat format = io::export_format_from(o.format);
  const std::filesystem::path input = o.input;
  const std::filesystem::path out = o.output.empty()
                                        ? std::filesystem::path(input).replace_extension(io::export_extension(format))
                                        : std::filesystem::path(o.output);
  if (std::filesystem::exists(out) && std::filesystem::exists(input) && std::filesystem::equivalent(out, input))
    throw InputError(out.string() + ": the output would overwrite the input: give another -o");
  const io::StoredFields fields = io::read_stored_fields_h5(input);
  io::export_fields(fields, format, out, input);
  std::fprintf(stderr, "%s: %zu arrays on %d x %d x %d nodes (%s) written as %s\n", out.string().c_str(),
               fields.arrays.size(), fields.grid.shape[0], fields.grid.shape[1], fields.grid.shape[2],
               fields.kind.c_str(), o.format.c_str());
  std::cout << out.string() << "\n";
}

}  // namespace

void add_export_commands(CLI::App& app) {
  auto o = std::make_shared<ExportOptions>();
  auto* cmd = app.add_subcommand(
      "export",
      "a vector field or volume file (HDF5) to Tecplot ASCII, NumPy .npz, CSV or NetCDF-4: every array the file "
      "holds, with the node coordinates x, y, z (mm) and units");
  cmd->add_option("file", o->input, "vector field (HDF5 /vectors) or volume (HDF5 /volume) file")->required();
  cmd->add_option("--to", o->format, "tecplot (.dat, POINT zone), npz, csv (one row per node) or netcdf (.nc, CF)")
      ->required();
  cmd->add_option("-o,--output", o->output, "output file (default: FILE with .dat, .npz, .csv or .nc)");
  cmd->callback([o] { run_export(*o); });
}

}  // namespace plenopiv::client
