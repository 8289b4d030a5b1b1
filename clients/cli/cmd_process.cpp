// `plenopiv process`: one frame pair from files (camera, calibration, frames A and B, run config)
// to a vector field in HDF5 and .vti and a PNG preview (core/plot: a slice, vectors over ω_z and w);
// `plenopiv process --run <folder>`: every pair of a run recorded by plenopivd, from the folder alone.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

#include <google/protobuf/util/json_util.h>
#include <tbb/parallel_invoke.h>

#include "clients/cli/calibration_frames.hpp"
#include "clients/cli/commands.hpp"
#include "clients/cli/options.hpp"
#include "clients/cli/png_file.hpp"
#include "clients/cli/progress.hpp"
#include "clients/cli/reprocess.hpp"
#include "clients/cli/weights_cache.hpp"
#include "core/base/errors.hpp"
#include "core/calib/calibration.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/raw_frame.hpp"
#include "core/io/vtk_files.hpp"
#include "core/optics/camera_file.hpp"
#include "core/plot/field_preview.hpp"
#include "core/process/field_file.hpp"
#include "core/process/frame_check.hpp"
#include "core/process/pair_processor.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"
#include "plenopiv.pb.h"
#include "proto/run_folder.hpp"

namespace plenopiv::client {
namespace {

struct ProcessOptions {
  std::string run, tier = "full", pairs, shard;
  int jobs = 1;
  bool resume = false, merge = false, prepare = false;
  std::optional<double> dt_s;
  std::string camera, frame_a, frame_b, config, calibration, calibration_image, output, vti, preview;
  std::vector<std::string> white_images, dark_images;
  bool nominal = false;
  int threads = 0;
  std::string cache_dir;
  bool no_cache = false;
};

// A raw frame (PNG, 8/16-bit or float TIFF) as floats; a frame with nothing to measure (all zero,
// saturated) is said on stderr under `name` and added to `warnings`.
ImageF read_frame(const std::string& path, const std::string& name, std::vector<std::string>& warnings) {
  ImageF image = io::read_raw_frame(path);
  if (const auto problem = process::frame_problem(image.pixels)) {
    warnings.push_back(name + " (" + path + ") " + *problem);
    std::fprintf(stderr, "warning: %s\n", warnings.back().c_str());
  }
  return image;
}

// Says on stderr when a field has no valid vector or hardly any: the frames or settings, not the
// flow, are then the likely cause.
void warn_if_few_valid(const VectorField& f, const std::string& what) {
  std::size_t valid = 0;
  for (auto v : f.valid) valid += v;
  if (f.valid.empty() || 10 * valid >= f.valid.size()) return;
  std::fprintf(stderr,
               "warning: %s: only %zu of %zu vectors valid: check the frames (light, focus, seeding) and "
               "the volume and correlation settings\n",
               what.c_str(), valid, f.valid.size());
}

// Says on stderr the field's typical uncertainty (the median sigma of u, v, w over the vectors
// that have one, m/s) and what it holds (sigma_method); nothing without one.
void say_uncertainty(const VectorField& f) {
  if (!f.has_sigma() || !(f.dt_s > 0)) return;
  double median_m_s[3] = {};
  std::size_t with_sigma = 0;
  const std::vector<float>* sigma[3] = {&f.sigma_dx_mm, &f.sigma_dy_mm, &f.sigma_dz_mm};
  for (int a = 0; a < 3; ++a) {
    std::vector<float> values;
    for (float s : *sigma[a])
      if (std::isfinite(s)) values.push_back(s);
    with_sigma = values.size();
    if (values.empty()) return;
    auto middle = values.begin() + std::ptrdiff_t(values.size() / 2);
    std::nth_element(values.begin(), middle, values.end());
    median_m_s[a] = double(*middle) * 1e-3 / f.dt_s;
  }
  std::fprintf(stderr, "uncertainty, median over %zu vectors: sigma u %.3g, v %.3g, w %.3g m/s\n  sigma: %s\n",
               with_sigma, median_m_s[0], median_m_s[1], median_m_s[2], f.sigma_method.c_str());
}

// The lens centres and white correction from exactly one of the three sources: a calibration
// file, calibration frames (white, optionally stopped-down and dark; calibrated as `plenopiv
// calibrate` does), or the nominal lattice.
calib::LoadedCalibration calibration_for(const ProcessOptions& o, const optics::CameraModel& camera) {
  const bool from_frames = !o.calibration_image.empty() || !o.white_images.empty() || !o.dark_images.empty();
  const int given = int(!o.calibration.empty()) + int(from_frames) + int(o.nominal);
  if (given != 1)
    throw InputError(
        "give exactly one of --calibration FILE.h5, --white FRAMES (optionally with "
        "--calibration-image and --dark), or --nominal");
  if (!o.calibration.empty()) return calib::load_calibration(o.calibration, camera);
  if (o.nominal) return calib::nominal_calibration(camera);
  if (o.white_images.empty()) throw InputError("--calibration-image and --dark need --white frame(s)");
  CalibrationFrameFiles files{o.white_images, {}, o.dark_images};
  if (!o.calibration_image.empty()) files.calibration.push_back(o.calibration_image);
  const calib::Calibration cal = calibrate_from_files(camera, files);
  return calib::loaded_calibration(cal);
}

// Frames given one by one that plenopivd recorded (frames/pair-<n>-A.tif in a run folder): the
// pair's measured dt is in the run's manifest, and without --dt the config's nominal dt is used
// instead, which is said.
void warn_if_recorded_dt_ignored(const ProcessOptions& o) {
  const std::filesystem::path frame = std::filesystem::absolute(o.frame_a);
  const std::filesystem::path run = frame.parent_path().parent_path();
  if (o.dt_s || frame.parent_path().filename() != "frames" || !std::filesystem::exists(run / "manifest.json")) return;
  try {
    const run_folder::Reader reader(run);
    for (const run_folder::PairEntry& p : reader.pairs()) {
      if (std::filesystem::equivalent(p.frame_a, frame) && p.measured_dt_s) {
        std::fprintf(stderr,
                     "warning: %s is pair %llu of run %s, whose laser pulses were %.9g s apart (measured); this uses "
                     "the config's nominal dt instead: give --dt %.9g, or use plenopiv process --run %s\n",
                     o.frame_a.c_str(), static_cast<unsigned long long>(p.pair_index), run.c_str(), *p.measured_dt_s,
                     *p.measured_dt_s, run.c_str());
      }
    }
  } catch (const InputError&) {
    // Not a readable run folder: nothing to compare with.
  }
}

void run_process(const ProcessOptions& o) {
  for (const auto& [value, name] :
       {std::pair{&o.camera, "--camera"}, std::pair{&o.frame_a, "frame_a"}, std::pair{&o.frame_b, "frame_b"},
        std::pair{&o.config, "--config"}, std::pair{&o.output, "--output"}})
    if (value->empty()) throw InputError(std::string(name) + " is required (or --run <run folder>)");
  for (const auto& [given, name] :
       {std::pair{o.resume, "--resume"}, std::pair{o.merge, "--merge"}, std::pair{o.prepare, "--prepare"},
        std::pair{!o.shard.empty(), "--shard"}, std::pair{!o.pairs.empty(), "--pairs"}})
    if (given) throw InputError(std::string(name) + " works on a recorded run: give it with --run <run folder>");
  const auto limit = thread_limit(o.threads);
  // Every input is read and checked before any long work starts.
  process::ProcessSettings settings = process::load_process_settings(o.config);
  if (o.dt_s) {
    if (!(*o.dt_s > 0) || !std::isfinite(*o.dt_s)) throw InputError("--dt: must be > 0 s");
    settings.correlation.dt_s = *o.dt_s;
  }
  warn_if_recorded_dt_ignored(o);
  const optics::CameraModel camera = optics::load_camera_file(o.camera);
  std::vector<std::string> warnings;
  const ImageF a = read_frame(o.frame_a, "frame A", warnings), b = read_frame(o.frame_b, "frame B", warnings);
  for (const auto* f : {&o.frame_a, &o.frame_b}) {
    const ImageF& img = f == &o.frame_a ? a : b;
    if (img.width != camera.sensor().width_px || img.height != camera.sensor().height_px)
      throw InputError(*f + ": frame is " + std::to_string(img.width) + " x " + std::to_string(img.height) +
                       ", the camera's sensor (" + o.camera + ") is " + std::to_string(camera.sensor().width_px) +
                       " x " + std::to_string(camera.sensor().height_px));
  }
  const std::filesystem::path out = o.output;
  const std::filesystem::path vti =
      o.vti.empty() ? std::filesystem::path(out).replace_extension(".vti") : std::filesystem::path(o.vti);
  const std::filesystem::path png =
      o.preview.empty() ? std::filesystem::path(out).replace_extension(".png") : std::filesystem::path(o.preview);
  for (const auto& p : {out, vti, png}) {
    const auto dir = p.parent_path().empty() ? std::filesystem::path(".") : p.parent_path();
    if (!std::filesystem::is_directory(dir))
      throw InputError(p.string() + ": folder " + dir.string() + " does not exist");
  }

  const calib::LoadedCalibration cal = calibration_for(o, camera);
  const auto& g = settings.grid;
  std::fprintf(stderr, "volume %d x %d x %d voxels (+%d guard slices at each depth end); weights ...\n", g.shape[0],
               g.shape[1], g.shape[2], settings.guard_slices());
  const auto operators = weights_cache(o.cache_dir, o.no_cache);
  const auto processor = make_pair_processor(camera, cal, settings, operators.get());
  Progress progress("process", "pairs", 1.0);
  process::PairOptions options;
  options.progress = [&](const std::string&, double f) { progress.update(f); };
  const auto r = processor->process(a, b, options);

  // What the field came from, with the input files' checksums (input_file_entry).
  char black_levels[512];
  std::snprintf(black_levels, sizeof black_levels, "%s; frame A %s, frame B %s counts",
                processor->black_level_note().c_str(), r.black_level_a.text().c_str(), r.black_level_b.text().c_str());
  const auto provenance = [&] {
    std::vector<io::TextAttribute> p{process::input_file_entry("frame_a", o.frame_a),
                                     process::input_file_entry("frame_b", o.frame_b),
                                     process::input_file_entry("camera", o.camera),
                                     {"settings", io::read_file_bytes(o.config)},
                                     {"settings_file", o.config},
                                     {"dt_s", std::to_string(r.correlation.field.dt_s)},
                                     {"dt_source", o.dt_s ? "--dt" : "nominal (dt_s of " + o.config + ")"},
                                     {"black_level", black_levels}};
    if (!o.calibration.empty()) {
      p.push_back(process::input_file_entry("calibration", o.calibration));
    } else if (o.nominal) {
      p.push_back({"calibration", "nominal (the camera file's lens array and a geometric white image)"});
    } else {
      for (std::size_t i = 0; i < o.white_images.size(); ++i)
        p.push_back(process::input_file_entry("white_image_" + std::to_string(i + 1), o.white_images[i]));
      for (std::size_t i = 0; i < o.dark_images.size(); ++i)
        p.push_back(process::input_file_entry("dark_image_" + std::to_string(i + 1), o.dark_images[i]));
      if (!o.calibration_image.empty())
        p.push_back(process::input_file_entry("calibration_image", o.calibration_image));
    }
    return p;
  };
  // The preview is drawn while the inputs' checksums are taken and the field files written; a
  // failure of the files is reported before one of the preview, whichever thread ends first.
  std::exception_ptr files_failed, preview_failed;
  tbb::parallel_invoke(
      [&] {
        try {
          process::write_vector_field_files(out, vti, r.correlation.field, r.correlation.flags, provenance());
        } catch (...) {
          files_failed = std::current_exception();
        }
      },
      [&] {
        try {
          plot::write_field_preview(png, r.correlation.field, r.correlation.flags);
        } catch (...) {
          preview_failed = std::current_exception();
        }
      });
  for (const std::exception_ptr& e : {files_failed, preview_failed})
    if (e) std::rethrow_exception(e);
  warn_if_few_valid(r.correlation.field, out.string());

  std::size_t valid = 0;
  for (auto v : r.correlation.field.valid) valid += v;
  std::fprintf(
      stderr,
      "black level taken off A %s, B %s counts; reconstruct A %.2f s (voxel updates skipped %.1f %%), B %.2f s "
      "(skipped %.1f %%), correlate %.2f s; %zu vectors, %zu valid\n",
      r.black_level_a.text().c_str(), r.black_level_b.text().c_str(), r.times.reconstruct_a_s,
      100 * r.skipped_a.fraction_updates_skipped(), r.times.reconstruct_b_s,
      100 * r.skipped_b.fraction_updates_skipped(), r.times.correlate_s, r.correlation.field.grid.count(), valid);
  say_uncertainty(r.correlation.field);
  std::cout << out.string() << "\n" << vti.string() << "\n" << png.string() << "\n";
}

// Every recorded pair again, from the run folder alone (clients/cli/reprocess.hpp): the run's own
// settings or offline ones, each pair's measured dt, ranges, jobs, resume, shards and the merge.
void run_reprocess(const ProcessOptions& o) {
  for (const auto* other :
       {&o.camera, &o.frame_a, &o.frame_b, &o.calibration, &o.calibration_image, &o.vti, &o.preview})
    if (!other->empty())
      throw InputError(
          "--run takes the camera, frames and calibration from the run folder; give --run with -o, "
          "--config, --tier, --pairs, --jobs, --resume, --shard, --merge, --prepare, --threads and the cache options "
          "only");
  if (!o.white_images.empty() || !o.dark_images.empty() || o.nominal)
    throw InputError("--run takes the calibration from the run folder (manifest.json: calibration)");
  if (o.dt_s) throw InputError("--dt: --run uses each pair's measured dt (the run's dt_s where none was measured)");
  const auto limit = thread_limit(o.threads);
  ReprocessOptions r;
  r.run = o.run;
  r.output = o.output;
  r.config = o.config;
  r.tier = o.tier;
  if (!o.pairs.empty()) r.pairs = parse_pair_range(o.pairs);
  if (!o.shard.empty()) r.shard = parse_shard(o.shard);
  r.jobs = o.jobs;
  r.resume = o.resume;
  r.merge_only = o.merge;
  r.prepare_only = o.prepare;
  r.weights_cache = weights_cache_folder(o.cache_dir, o.no_cache);
  if (r.merge_only && r.shard) throw InputError("--merge covers every pair: give it without --shard");
  if (r.prepare_only && (r.merge_only || r.shard || r.resume))
    throw InputError("--prepare processes no pair: give it without --merge, --shard and --resume");
  const ReprocessReport report = reprocess_run(r);
  if (r.prepare_only) {
    std::fprintf(stderr, "%s: prepared for %zu pair(s): the weight tables%s in %s\n", report.output.string().c_str(),
                 report.selected, report.depth_response ? " and the depth response" : "",
                 r.weights_cache.string().c_str());
    std::cout << r.weights_cache.string() << "\n";
    return;
  }
  std::fprintf(stderr, "%s: %zu pair(s) selected, %zu processed, %zu up to date%s\n", report.output.string().c_str(),
               report.selected, report.processed, report.skipped,
               report.merged ? "; statistics.h5 and series.pvd written" : "");
  std::cout << report.output.string() << "\n";
}

}  // namespace

void add_process_commands(CLI::App& app) {
  auto o = std::make_shared<ProcessOptions>();
  auto* cmd = app.add_subcommand(
      "process", "one frame pair to a 3D/3C vector field: reconstruct A and B (MART), correlate (multi-pass)");
  cmd->add_option("--run", o->run,
                  "a run folder recorded by plenopivd: reprocess its pairs (each with its measured dt) with the run's "
                  "own settings or --config, camera and calibration into <run>/reprocessed/ (or -o DIR), with "
                  "statistics.h5 and series.pvd");
  add_camera_option(cmd, o->camera);
  cmd->add_option("frame_a", o->frame_a, "raw plenoptic frame A (PNG, or TIFF of 8/16-bit or float; sensor-sized)");
  cmd->add_option("frame_b", o->frame_b, "raw plenoptic frame B");
  cmd->add_option("-c,--config", o->config,
                  "processing spec YAML: dt_s, volume {x_mm, y_mm, z_mm, voxel_mm}, reconstruction, correlation "
                  "(systemd/config/process.yaml); with --run: offline settings instead of the run's (or 'run')");
  cmd->add_option("--calibration", o->calibration, "calibration file (HDF5, from `plenopiv calibrate`)");
  cmd->add_option("--calibration-image", o->calibration_image,
                  "calibration frame (aperture stopped down), with --white; without it the centres come from the "
                  "white");
  cmd->add_option("--white", o->white_images, "white frame(s) (averaged): calibrate from them as `plenopiv calibrate`");
  cmd->add_option("--dark", o->dark_images, "dark frame(s) for --white (averaged, subtracted)");
  cmd->add_flag("--nominal", o->nominal,
                "no calibration: the camera's nominal lattice and geometric white image "
                "(simulated frames)");
  cmd->add_option("-o,--output", o->output,
                  "vector field (HDF5 /vectors with vorticity and flags); with --run, the output folder");
  cmd->add_option("--vti", o->vti, "VTK image data for ParaView (default: --output with .vti)");
  cmd->add_option("--preview", o->preview, "PNG preview (default: --output with .png)");
  add_threads_option(cmd, o->threads);
  cmd->add_option("--cache-dir", o->cache_dir,
                  "folder that keeps weight tables between calls, keyed by camera, calibration, volume and "
                  "settings (default: $PLENOPIV_CACHE_DIR, $XDG_CACHE_HOME/plenopiv or ~/.cache/plenopiv)");
  cmd->add_flag("--no-cache", o->no_cache, "build the weight tables afresh and keep none");
  cmd->add_option("--dt", o->dt_s, "pulse separation, s (instead of the config's dt_s): a pair's measured dt");
  cmd->add_option("--tier", o->tier, "with --run: the settings' tier, full or live (the live lane's)")
      ->capture_default_str();
  cmd->add_option("--pairs", o->pairs, "with --run: pair indices a:b (b excluded; a: or :b)");
  cmd->add_option("--jobs", o->jobs, "with --run: pairs processed at once (each needs its own buffers)")
      ->capture_default_str();
  cmd->add_flag("--resume", o->resume, "with --run: skip pairs whose output is there with the same inputs");
  cmd->add_option("--shard", o->shard, "with --run: process shard i/n of the pairs only (a cluster task); merge later");
  cmd->add_flag("--merge", o->merge,
                "with --run: only check every pair's output and write statistics.h5 and series.pvd");
  cmd->add_flag("--prepare", o->prepare,
                "with --run: only make the weight tables and the depth response (if the settings ask for one) in "
                "the cache folder, for the calls after it (a cluster submission's first job)");
  cmd->callback([o] { o->run.empty() ? run_process(*o) : run_reprocess(*o); });
}

}  // namespace plenopiv::client
