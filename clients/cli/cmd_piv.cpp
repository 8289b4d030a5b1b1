// `plenopiv correlate`: two volume files -> a 3D/3C vector field (HDF5, ParaView .vti, a PNG preview).
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>

#include "clients/cli/commands.hpp"
#include "clients/cli/options.hpp"
#include "clients/cli/progress.hpp"
#include "core/base/errors.hpp"
#include "core/io/checksum.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/vtk_files.hpp"
#include "core/piv/derived.hpp"
#include "core/piv/multipass.hpp"
#include "core/plot/field_preview.hpp"
#include "core/process/field_file.hpp"

namespace plenopiv::client {
namespace {

struct CorrelateOptions {
  std::string first, second, output, vti, preview, config, passes;
  std::optional<double> dt_s;
  std::optional<float> signal_threshold;
  std::optional<double> intensity_threshold;
  std::optional<int> final_smoothing;
  std::optional<int> depth_prefilter;
  std::string fft_planning;
  bool no_prefilter = false;
  int threads = 0;
};

std::string pass_line(const piv::PassReport& r) {
  const auto& w = r.settings.window;
  const auto& v = r.validation;
  const double seconds = r.deform_s + r.correlate_s + r.validate_s;
  char line[512];
  std::snprintf(line, sizeof line,
                "pass %d/%d: windows %dx%dx%d, overlap %.0f %%, depth margin %d, %dx%dx%d vectors (%zu without "
                "signal); outliers %zu (2nd peak %zu, 3rd peak %zu, interpolated %zu, "
                "unresolved %zu); fallback fits %zu parabolic, %zu centroid; %.2f s (deform "
                "%.2f, correlate %.2f, %.0f windows/s)",
                r.pass, r.passes, w[0], w[1], w[2], r.settings.overlap_percent, r.settings.depth_margin, r.vectors[0],
                r.vectors[1], r.vectors[2], r.no_signal, v.outliers, v.second_peak, v.third_peak, v.interpolated,
                v.unresolved, r.flag_parabolic, r.flag_centroid, seconds, r.deform_s, r.correlate_s,
                r.correlate_s > 0 ? double(r.windows) / r.correlate_s : 0.0);
  std::string out = line;
  if (r.near_peaks || r.near_rejected)
    out += "; peaks at the predictor without the FFT " + std::to_string(r.near_peaks) + " (and " +
           std::to_string(r.near_rejected) + " more rejected by the median test, searched over all shifts)";
  return out;
}

void run_correlate(const CorrelateOptions& o) {
  piv::CorrelationSettings settings;
  if (!o.config.empty()) settings = piv::load_correlation_settings(o.config);
  if (!o.passes.empty()) settings.passes = piv::parse_passes(o.passes);
  if (o.dt_s) settings.dt_s = *o.dt_s;
  if (o.signal_threshold) settings.signal_threshold = *o.signal_threshold;
  if (o.intensity_threshold) settings.intensity_threshold_of_mean = *o.intensity_threshold;
  if (o.final_smoothing) settings.final_smoothing = *o.final_smoothing;
  if (o.depth_prefilter) settings.depth_prefilter = *o.depth_prefilter;
  if (o.no_prefilter) settings.prefilter = false;
  if (o.fft_planning == "measure") settings.fft_planning = piv::FftPlanning::measure;
  if (o.fft_planning == "estimate") settings.fft_planning = piv::FftPlanning::estimate;
  if (o.config.empty() && !o.dt_s)
    throw InputError("--dt: the pulse separation (s) is needed for velocities (or dt_s in --config)");
  piv::check(settings, o.config.empty() ? "command line" : o.config);
  const auto limit = thread_limit(o.threads);

  for (const std::string* file : {&o.output, &o.vti, &o.preview}) {
    const auto folder = std::filesystem::path(*file).parent_path();
    if (!file->empty() && !folder.empty() && !std::filesystem::is_directory(folder))
      throw InputError(*file + ": folder " + folder.string() + " does not exist");
  }
  const Volume a = io::read_volume_h5(o.first);
  const Volume b = io::read_volume_h5(o.second);
  if (!(a.grid == b.grid))
    throw InputError(o.first + " and " + o.second + " are on different grids (" + std::to_string(a.grid.shape[0]) +
                     "x" + std::to_string(a.grid.shape[1]) + "x" + std::to_string(a.grid.shape[2]) + " vs " +
                     std::to_string(b.grid.shape[0]) + "x" + std::to_string(b.grid.shape[1]) + "x" +
                     std::to_string(b.grid.shape[2]) +
                     " voxels, or different origin/spacing): correlate volumes of one grid");
  // A pass is the unit of progress: one line each with its counts, and on a terminal the shared
  // bar (rate and ETA in passes) below the lines.
  const bool terminal = isatty(STDERR_FILENO);
  Progress bar("correlate", "passes", double(settings.passes.size()));
  if (settings.depth_prefilter > 0)
    std::cerr << "prefilter: " << settings.depth_prefilter << " more binomial pass"
              << (settings.depth_prefilter > 1 ? "es" : "") << " along depth (z)\n";
  const auto result = piv::correlate_volumes(a, b, settings, [&](const piv::PassReport& r) {
    if (terminal) std::cerr << "\r\033[K";
    std::cerr << pass_line(r) << "\n";
    if (terminal) bar.update(double(r.pass) / r.passes);
  });
  if (settings.final_smoothing > 0)
    std::cerr << "final field: " << settings.final_smoothing << " binomial smoothing pass"
              << (settings.final_smoothing > 1 ? "es" : "") << " over the valid vectors\n";

  const std::filesystem::path vti = o.vti.empty() ? std::filesystem::path() : std::filesystem::path(o.vti);
  std::vector<io::TextAttribute> provenance{process::input_file_entry("volume_a", o.first),
                                            process::input_file_entry("volume_b", o.second)};
  if (!o.config.empty()) provenance.push_back({"settings", io::read_file_bytes(o.config)});
  process::write_vector_field_files(o.output, vti, result.field, result.flags, provenance);
  std::size_t valid = 0;
  for (auto v : result.field.valid) valid += v;
  std::cout << o.output << ": " << result.field.grid.count() << " vectors, " << valid << " valid\n";
  if (!o.vti.empty()) {
    std::cout << o.vti << ": written\n";
  }
  if (!o.preview.empty()) {
    plot::write_field_preview(o.preview, result.field, result.flags);
    std::cout << o.preview << ": written\n";
  }
}

}  // namespace

void add_piv_commands(CLI::App& app) {
  auto o = std::make_shared<CorrelateOptions>();  // owned by the callback, which the app keeps
  auto* cmd = app.add_subcommand("correlate", "cross-correlate two volumes (HDF5) into a 3D/3C vector field (sec 6.3)");
  cmd->add_option("first", o->first, "volume of exposure A (HDF5 /volume)")->required();
  cmd->add_option("second", o->second, "volume of exposure B, same grid")->required();
  cmd->add_option("-o,--output", o->output, "vector field to write (HDF5 /vectors)")->required();
  cmd->add_option("--vti", o->vti, "also write VTK image data for ParaView");
  cmd->add_option("--preview", o->preview,
                  "also write a PNG preview: the middle x-y slice, vectors over vorticity and w");
  cmd->add_option("-c,--config", o->config,
                  "YAML with passes, median, signal_threshold, dt_s, predictor, ... (flags override it)");
  cmd->add_option("--passes", o->passes,
                  "coarse to fine, e.g. 32@50,24@75,16@75 or 32x32x64@50; +M: the second window reaches M voxels "
                  "further in depth (default 32@50,16@50+4,16@50,16@75)");
  cmd->add_option("--dt", o->dt_s, "pulse separation, s (velocity = displacement / dt)");
  cmd->add_option("--signal-threshold", o->signal_threshold,
                  "windows whose brightest voxel is not above this are skipped (default 0)");
  cmd->add_option("--intensity-threshold", o->intensity_threshold,
                  "subtract this many times each volume's mean intensity first: removes a reconstruction's "
                  "ghost haze (default 0: off; 4 measured best on MART volumes)");
  cmd->add_option("--final-smoothing", o->final_smoothing,
                  "binomial [1 2 1]/4 passes over the final field's valid vectors, 0 to 4: less random error, "
                  "less resolution (default 0: off, the paper's correlation)");
  cmd->add_option("--depth-prefilter", o->depth_prefilter,
                  "after the prefilter, this many more binomial [1 2 1]/4 passes along depth (z) "
                  "only, 0 to 8: MART's particles are ~4x as long in depth as wide (default 0: "
                  "off; 4 measured best on MART volumes)");
  cmd->add_option("--fft-planning", o->fft_planning,
                  "estimate (default; bit-identical between runs) or measure (faster FFTs)")
      ->check(CLI::IsMember({"estimate", "measure"}));
  cmd->add_flag("--no-prefilter", o->no_prefilter,
                "correlate the volumes as they are (default: binomial smoothing first)");
  add_threads_option(cmd, o->threads);
  cmd->callback([o] { run_correlate(*o); });
}

}  // namespace plenopiv::client
