// `plenopiv process`: one frame pair from files (camera, calibration, frames A and B, run config)
// to a vector field in HDF5 and .vti and a PNG preview (a slice with vectors over vorticity);
// `plenopiv process --run <folder>`: every pair of a run recorded by plenopivd, from the folder alone.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <google/protobuf/util/json_util.h>
#include <tbb/global_control.h>

#include "clients/cli/commands.hpp"
#include "clients/cli/progress.hpp"
#include "core/base/errors.hpp"
#include "core/calib/calibration.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"
#include "core/io/vtk_files.hpp"
#include "core/optics/camera_file.hpp"
#include "core/piv/derived.hpp"
#include "core/process/operator_cache.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"
#include "plenopiv.pb.h"

namespace plenopiv::client {
namespace {

struct ProcessOptions {
  std::string run;
  std::string camera, frame_a, frame_b, config, calibration, calibration_image, output, vti, preview;
  std::vector<std::string> white_images;
  bool nominal = false;
  int threads = 0;
  std::string cache_dir;
  bool no_cache = false;
};

// The weight tables' cache (core/process): --cache-dir, else the default folder; none with
// --no-cache or when no folder is known (said).
std::unique_ptr<process::WeightsDiskCache> weights_cache(const std::string& dir, bool off) {
  if (off) return nullptr;
  const std::filesystem::path folder = dir.empty() ? process::default_cache_folder() : std::filesystem::path(dir);
  if (folder.empty()) {
    std::fprintf(stderr, "weight tables are not cached: no --cache-dir, PLENOPIV_CACHE_DIR, XDG_CACHE_HOME or HOME\n");
    return nullptr;
  }
  return std::make_unique<process::WeightsDiskCache>(folder);
}

ImageF read_frame(const std::string& path) {
  const ImageU16 raw = io::read_tiff_u16(path);
  ImageF image(raw.width, raw.height);
  for (std::size_t i = 0; i < raw.size(); ++i) image.pixels[i] = raw.pixels[i];
  return image;
}

// The lens centres and white correction from exactly one of the three sources.
calib::LoadedCalibration calibration_for(const ProcessOptions& o, const optics::CameraModel& camera) {
  const int given = int(!o.calibration.empty()) + int(!o.calibration_image.empty()) + int(o.nominal);
  if (given != 1)
    throw InputError("give exactly one of --calibration FILE.h5, --calibration-image TIFF (with --white), "
                     "or --nominal");
  if (!o.calibration.empty()) return calib::load_calibration(o.calibration, camera);
  if (o.nominal) return calib::nominal_calibration(camera);
  if (o.white_images.empty()) throw InputError("--calibration-image: needs at least one --white image");
  calib::Calibration cal = calib::calibrate(camera, read_frame(o.calibration_image));
  ImageF white;
  for (const std::string& path : o.white_images) {
    const ImageF w = read_frame(path);
    if (w.width != camera.sensor().width_px || w.height != camera.sensor().height_px)
      throw InputError(path + ": white image is " + std::to_string(w.width) + " x " + std::to_string(w.height) +
                       ", the camera's sensor is " + std::to_string(camera.sensor().width_px) + " x " +
                       std::to_string(camera.sensor().height_px));
    if (white.empty()) white = ImageF(w.width, w.height, 0.0f);
    for (std::size_t k = 0; k < w.size(); ++k) white.pixels[k] += w.pixels[k] / float(o.white_images.size());
  }
  cal.white_correction = calib::make_white_correction(cal, white, cal.image_stats.background);
  return {cal.microlens_array(), cal.white_correction};
}

// The x-y slice through the middle of the vector grid: in-plane vectors over the out-of-plane
// vorticity ω_z (colour, symmetric scale), with a colour bar and the scales written out.
cv::Mat preview_image(const VectorField& f, const std::vector<float>& omega_z) {
  const int nx = f.grid.shape[0], ny = f.grid.shape[1], k = f.grid.shape[2] / 2;
  const int cell = std::max(8, 640 / std::max(nx, ny));
  const int w = nx * cell, h = ny * cell, bar = 100, top = 30;
  const auto idx = [&](int i, int j) { return (std::size_t(k) * ny + j) * nx + i; };
  double omega_max = 0, disp_max = 0;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const auto n = idx(i, j);
      if (!f.valid[n]) continue;
      if (std::isfinite(omega_z[n])) omega_max = std::max(omega_max, double(std::abs(omega_z[n])));
      disp_max = std::max(disp_max, std::hypot(double(f.dx_mm[n]), double(f.dy_mm[n])));
    }
  if (!(omega_max > 0)) omega_max = 1;
  cv::Mat level(ny, nx, CV_8U), invalid(ny, nx, CV_8U);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const auto n = idx(i, j);
      const bool ok = f.valid[n] && std::isfinite(omega_z[n]);
      invalid.at<std::uint8_t>(j, i) = ok ? 0 : 255;
      level.at<std::uint8_t>(j, i) = ok ? cv::saturate_cast<std::uint8_t>(127.5 + 127.5 * omega_z[n] / omega_max) : 0;
    }
  cv::Mat coloured, big_invalid;
  cv::applyColorMap(level, coloured, cv::COLORMAP_JET);
  cv::resize(coloured, coloured, {w, h}, 0, 0, cv::INTER_NEAREST);
  cv::resize(invalid, big_invalid, {w, h}, 0, 0, cv::INTER_NEAREST);
  coloured.setTo(cv::Scalar(128, 128, 128), big_invalid);

  cv::Mat canvas(h + top, w + bar, CV_8UC3, cv::Scalar(255, 255, 255));
  coloured.copyTo(canvas(cv::Rect(0, top, w, h)));
  // Arrows centred on their node; the longest in-plane displacement spans 0.9 cell.
  const double scale = disp_max > 0 ? 0.9 * cell / disp_max : 0;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const auto n = idx(i, j);
      if (!f.valid[n]) continue;
      const cv::Point2d c((i + 0.5) * cell, top + (j + 0.5) * cell);
      const cv::Point2d half(0.5 * f.dx_mm[n] * scale, 0.5 * f.dy_mm[n] * scale);
      cv::arrowedLine(canvas, c - half, c + half, cv::Scalar(0, 0, 0), 1, cv::LINE_AA, 0, 0.25);
    }
  // Colour bar from -ω_max (bottom) to +ω_max (top).
  for (int r = 0; r < h; ++r) {
    cv::Mat one(1, 1, CV_8U, cv::Scalar(255 - 255 * r / std::max(h - 1, 1))), c;
    cv::applyColorMap(one, c, cv::COLORMAP_JET);
    cv::line(canvas, {w + 20, top + r}, {w + 40, top + r}, cv::Scalar(c.at<cv::Vec3b>(0, 0)));
  }
  char text[128];
  const auto label = [&](const char* s, cv::Point at) {
    cv::putText(canvas, s, at, cv::FONT_HERSHEY_SIMPLEX, 0.35, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  };
  std::snprintf(text, sizeof text, "%+.3g", omega_max);
  label(text, {w + 43, top + 10});
  label("0", {w + 43, top + h / 2});
  std::snprintf(text, sizeof text, "%+.3g", -omega_max);
  label(text, {w + 43, top + h - 2});
  label("wz 1/s", {w + 43, top + h / 2 + 14});
  const double z_mm = f.grid.origin_mm[2] + k * f.grid.spacing_mm[2];
  std::snprintf(text, sizeof text, "slice z = %.3f mm; longest arrow %.4g mm (%.4g m/s); grey: invalid", z_mm,
                disp_max, f.dt_s > 0 ? disp_max * 1e-3 / f.dt_s : 0.0);
  label(text, {4, 18});
  return canvas;
}

void write_png(const std::filesystem::path& path, const cv::Mat& image) {
  std::vector<std::uint8_t> bytes;
  if (!cv::imencode(".png", image, bytes)) throw InputError(path.string() + ": PNG encoding failed");
  io::write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    if (!out) throw InputError(path.string() + ": cannot write");
  });
}

// The vector field with vorticity and flags, as HDF5 and as VTK image data.
void write_field(const std::filesystem::path& h5, const std::filesystem::path& vti,
                 const piv::CorrelationResult& r, const std::array<std::vector<float>, 3>& omega) {
  std::vector<float> flags(r.flags.begin(), r.flags.end());
  io::write_vector_field_h5(h5, r.field,
                            {{"vorticity_x", omega[0]}, {"vorticity_y", omega[1]}, {"vorticity_z", omega[2]},
                             {"flags", flags}});
  std::vector<float> omega_vec(3 * omega[0].size());
  for (std::size_t i = 0; i < omega[0].size(); ++i)
    for (int c = 0; c < 3; ++c) omega_vec[3 * i + std::size_t(c)] = omega[std::size_t(c)][i];
  io::write_vector_field_vti(vti, r.field, {{"vorticity_1_s_vec", omega_vec}, {"flags", flags}});
}

std::optional<tbb::global_control> thread_limit(int threads) {
  if (threads < 0) throw InputError("--threads: must be >= 0 (0: all cores)");
  std::optional<tbb::global_control> limit;
  if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, threads);
  return limit;
}

void run_process(const ProcessOptions& o) {
  for (const auto& [value, name] : {std::pair{&o.camera, "camera"}, std::pair{&o.frame_a, "frame_a"},
                                    std::pair{&o.frame_b, "frame_b"}, std::pair{&o.config, "--config"},
                                    std::pair{&o.output, "--output"}})
    if (value->empty()) throw InputError(std::string(name) + " is required (or --run <run folder>)");
  const auto limit = thread_limit(o.threads);
  // Every input is read and checked before any long work starts.
  const process::ProcessSettings settings = process::load_process_settings(o.config);
  const optics::CameraModel camera = optics::load_camera_file(o.camera);
  const ImageF a = read_frame(o.frame_a), b = read_frame(o.frame_b);
  for (const auto* f : {&o.frame_a, &o.frame_b}) {
    const ImageF& img = f == &o.frame_a ? a : b;
    if (img.width != camera.sensor().width_px || img.height != camera.sensor().height_px)
      throw InputError(*f + ": frame is " + std::to_string(img.width) + " x " + std::to_string(img.height) +
                       ", the camera's sensor (" + o.camera + ") is " + std::to_string(camera.sensor().width_px) +
                       " x " + std::to_string(camera.sensor().height_px));
  }
  const std::filesystem::path out = o.output;
  const std::filesystem::path vti = o.vti.empty() ? std::filesystem::path(out).replace_extension(".vti") : std::filesystem::path(o.vti);
  const std::filesystem::path png =
      o.preview.empty() ? std::filesystem::path(out).replace_extension(".png") : std::filesystem::path(o.preview);
  for (const auto& p : {out, vti, png}) {
    const auto dir = p.parent_path().empty() ? std::filesystem::path(".") : p.parent_path();
    if (!std::filesystem::is_directory(dir)) throw InputError(p.string() + ": folder " + dir.string() + " does not exist");
  }

  const calib::LoadedCalibration cal = calibration_for(o, camera);
  const auto& g = settings.grid;
  std::fprintf(stderr, "volume %d x %d x %d voxels (+%d guard slices at each depth end); weights ...\n", g.shape[0],
               g.shape[1], g.shape[2], settings.guard_slices());
  const auto cache = weights_cache(o.cache_dir, o.no_cache);
  const process::PairOperator op(camera, cal.lenses, cal.white_correction, settings,
                                 cache ? cache->source() : process::PairOperator::WeightsSource{});
  if (cache) std::fprintf(stderr, "%s\n", cache->last_note().c_str());
  if (!op.note().empty()) std::fprintf(stderr, "%s\n", op.note().c_str());
  Progress progress("process", "pairs", 1.0);
  const auto r = process::process_pair(op, a, b, settings, [&](const std::string&, double f) { progress.update(f); });

  const auto omega = piv::vorticity(r.correlation.field);
  write_field(out, vti, r.correlation, omega);
  write_png(png, preview_image(r.correlation.field, omega[2]));

  std::size_t valid = 0;
  for (auto v : r.correlation.field.valid) valid += v;
  std::fprintf(stderr,
               "reconstruct A %.2f s (voxel updates skipped %.1f %%), B %.2f s (skipped %.1f %%), correlate %.2f s; "
               "%zu vectors, %zu valid\n",
               r.times.reconstruct_a_s, 100 * r.skipped_a.fraction_updates_skipped(), r.times.reconstruct_b_s,
               100 * r.skipped_b.fraction_updates_skipped(), r.times.correlate_s, r.correlation.field.grid.count(),
               valid);
  std::cout << out.string() << "\n" << vti.string() << "\n" << png.string() << "\n";
}

// A file the manifest names, inside the run folder; missing is an InputError naming key and file.
std::filesystem::path run_file(const std::filesystem::path& run, const std::string& key, const std::string& name) {
  const std::filesystem::path manifest = run / "manifest.json";
  if (name.empty())
    throw InputError(manifest.string() + ": " + key + " is empty: the run folder does not say where it is");
  const std::filesystem::path path = run / name;
  if (!std::filesystem::is_regular_file(path))
    throw InputError(manifest.string() + ": " + key + ": " + path.string() + " is missing");
  return path;
}

// Every recorded pair again, from the run folder alone: process.yaml (the live settings),
// camera.yaml, the calibration the manifest names (nominal, or the run's calibration.h5, whose
// size and CRC-32 must match the manifest's), frames/, and each pair's measured dt as the
// live path used it (the run's dt_s when none was measured).
void run_reprocess(const ProcessOptions& o) {
  for (const auto* other : {&o.camera, &o.frame_a, &o.frame_b, &o.config, &o.calibration, &o.calibration_image,
                            &o.vti, &o.preview})
    if (!other->empty())
      throw InputError("--run takes the camera, frames, settings and calibration from the run folder; "
                       "give only --run, -o, --threads and the cache options");
  if (!o.white_images.empty() || o.nominal)
    throw InputError("--run takes the calibration from the run folder (manifest.json: calibration)");
  const auto limit = thread_limit(o.threads);
  const std::filesystem::path run = o.run;
  if (!std::filesystem::is_directory(run)) throw InputError("--run: " + run.string() + " is not a folder");

  // Every input is read and checked before any long work starts.
  const std::filesystem::path manifest_path = run / "manifest.json";
  std::ifstream in(manifest_path);
  if (!in) throw InputError(manifest_path.string() + ": missing (not a plenopivd run folder?)");
  std::stringstream text;
  text << in.rdbuf();
  msg::RunManifest m;
  if (const auto status = google::protobuf::util::JsonStringToMessage(text.str(), &m); !status.ok())
    throw InputError(manifest_path.string() + ": not a run manifest: " + std::string(status.message()));
  const process::ProcessSettings settings = process::load_process_settings(run_file(run, "process_file", m.process_file()));
  const std::filesystem::path camera_path = run_file(run, "camera_file", m.camera_file());
  const optics::CameraModel camera = optics::load_camera_file(camera_path);
  std::optional<std::filesystem::path> calibration_copy;
  if (m.calibration() == "file") {
    // The run's own copy, checked against what the daemon recorded when it copied it.
    calibration_copy = run_file(run, "calibration_file", m.calibration_file());
    const std::string bytes = io::read_file_bytes(*calibration_copy);
    const std::string crc = io::crc32_hex(io::crc32_of(bytes));
    if (bytes.size() != m.calibration_bytes() || crc != m.calibration_crc32())
      throw InputError(calibration_copy->string() + ": " + std::to_string(bytes.size()) + " bytes, crc32 " + crc +
                       "; the manifest recorded " + std::to_string(m.calibration_bytes()) + " bytes, crc32 " +
                       m.calibration_crc32() + " (the copy was changed or damaged)");
  } else if (m.calibration() != "nominal") {
    throw InputError(manifest_path.string() + ": calibration: '" + m.calibration() +
                     "' is not one this version can reprocess with (nominal, file)");
  }
  if (m.pairs_size() == 0) throw InputError(manifest_path.string() + ": pairs: the run recorded no pair");
  for (const msg::ManifestPair& p : m.pairs()) {
    run_file(run, "pairs[" + std::to_string(p.pair_index()) + "].frame_a", p.frame_a());
    run_file(run, "pairs[" + std::to_string(p.pair_index()) + "].frame_b", p.frame_b());
  }
  const std::filesystem::path out_dir = o.output.empty() ? run / "reprocessed" : std::filesystem::path(o.output);
  std::filesystem::create_directories(out_dir);

  ProcessOptions source;
  if (calibration_copy) {
    source.calibration = calibration_copy->string();
  } else {
    source.nominal = true;
  }
  const calib::LoadedCalibration cal = calibration_for(source, camera);
  const auto& g = settings.grid;
  std::fprintf(stderr, "%s: %d pairs; volume %d x %d x %d voxels (+%d guard slices at each depth end); weights ...\n",
               run.string().c_str(), m.pairs_size(), g.shape[0], g.shape[1], g.shape[2], settings.guard_slices());
  const auto cache = weights_cache(o.cache_dir, o.no_cache);
  const process::PairOperator op(camera, cal.lenses, cal.white_correction, settings,
                                 cache ? cache->source() : process::PairOperator::WeightsSource{});
  if (cache) std::fprintf(stderr, "%s\n", cache->last_note().c_str());
  if (!op.note().empty()) std::fprintf(stderr, "%s\n", op.note().c_str());
  const double pairs = double(m.pairs_size());
  Progress progress("process", "pairs", pairs);
  recon::MartWorkspace workspace;  // MART's buffers, kept from pair to pair
  for (int k = 0; k < m.pairs_size(); ++k) {
    const msg::ManifestPair& p = m.pairs(k);
    const ImageF a = read_frame((run / p.frame_a()).string()), b = read_frame((run / p.frame_b()).string());
    process::ProcessSettings s = settings;
    if (p.measured_dt_s() > 0) s.correlation.dt_s = p.measured_dt_s();
    const auto r = process::process_pair(op, a, b, s, [&](const std::string&, double f) {
      progress.update((k + f) / pairs);
    }, &workspace);
    char name[32];
    std::snprintf(name, sizeof name, "pair-%06llu", static_cast<unsigned long long>(p.pair_index()));
    const std::filesystem::path h5 = out_dir / (std::string(name) + ".h5");
    write_field(h5, out_dir / (std::string(name) + ".vti"), r.correlation, piv::vorticity(r.correlation.field));
    std::cout << h5.string() << "\n";
  }
}

}  // namespace

void add_process_commands(CLI::App& app) {
  auto o = std::make_shared<ProcessOptions>();
  auto* cmd = app.add_subcommand(
      "process", "one frame pair to a 3D/3C vector field: reconstruct A and B (MART), correlate (multi-pass)");
  cmd->add_option("--run", o->run,
                  "a run folder recorded by plenopivd: reprocess every pair with the run's own settings, "
                  "camera and calibration into <run>/reprocessed/ (or -o DIR)");
  cmd->add_option("camera", o->camera, "camera file (YAML)");
  cmd->add_option("frame_a", o->frame_a, "raw plenoptic frame A (16-bit TIFF, sensor-sized)");
  cmd->add_option("frame_b", o->frame_b, "raw plenoptic frame B");
  cmd->add_option("--config", o->config,
                  "run config YAML: dt_s, volume {x_mm, y_mm, z_mm, voxel_mm}, reconstruction, correlation "
                  "(systemd/config/process.yaml)");
  cmd->add_option("--calibration", o->calibration, "calibration file (HDF5, from `plenopiv calibrate`)");
  cmd->add_option("--calibration-image", o->calibration_image, "calibration TIFF (aperture stopped down)");
  cmd->add_option("--white", o->white_images, "white TIFF(s) for --calibration-image (averaged)");
  cmd->add_flag("--nominal", o->nominal, "no calibration: the camera's nominal lattice and geometric white image "
                                          "(simulated frames)");
  cmd->add_option("-o,--output", o->output,
                  "vector field (HDF5 /vectors with vorticity and flags); with --run, the output folder");
  cmd->add_option("--vti", o->vti, "VTK image data for ParaView (default: --output with .vti)");
  cmd->add_option("--preview", o->preview, "PNG preview (default: --output with .png)");
  cmd->add_option("--threads", o->threads, "worker threads (0: all cores)")->capture_default_str();
  cmd->add_option("--cache-dir", o->cache_dir,
                  "folder that keeps weight tables between calls, keyed by camera, calibration, volume and "
                  "settings (default: $PLENOPIV_CACHE_DIR, $XDG_CACHE_HOME/plenopiv or ~/.cache/plenopiv)");
  cmd->add_flag("--no-cache", o->no_cache, "build the weight tables afresh and keep none");
  cmd->callback([o] { o->run.empty() ? run_process(*o) : run_reprocess(*o); });
}

}  // namespace plenopiv::client
