// The run folder: raw frames, vector fields, statistics and a manifest that always matches the disk.
#include "daemon/recorder.hpp"

#include <google/protobuf/util/json_util.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <future>
#include <sstream>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"

namespace plenopiv::daemon {
namespace fs = std::filesystem;
namespace {

std::string utc_now(const char* format) {
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&now, &tm);
  char text[64];
  std::strftime(text, sizeof text, format, &tm);
  return text;
}

std::string pair_name(std::uint64_t index) {
  char text[32];
  std::snprintf(text, sizeof text, "pair-%06llu", static_cast<unsigned long long>(index));
  return text;
}

void write_text(const fs::path& path, const std::string& text) {
  io::write_atomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw std::runtime_error("cannot write " + tmp.string());
  });
}

std::string manifest_json(const msg::RunManifest& manifest) {
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  options.always_print_primitive_fields = true;
  options.preserve_proto_field_names = true;
  std::string json;
  const auto status = google::protobuf::util::MessageToJsonString(manifest, &json, options);
  if (!status.ok()) throw std::runtime_error("manifest: " + status.ToString());
  return json;
}

}  // namespace

std::string new_run_id() { return utc_now("%Y%m%d-%H%M%S"); }

std::vector<fs::path> mark_interrupted_runs(const fs::path& data_dir, std::vector<std::string>* problems) {
  std::vector<fs::path> marked;
  std::error_code ec;
  fs::directory_iterator it(data_dir, ec);
  if (ec) return marked;  // no data directory yet: nothing was interrupted
  for (const auto& entry : it) {
    const fs::path manifest_file = entry.path() / "manifest.json";
    if (entry.path().filename().string().rfind("run-", 0) != 0 || !fs::is_regular_file(manifest_file, ec)) continue;
    try {
      std::ifstream in(manifest_file, std::ios::binary);
      std::stringstream text;
      text << in.rdbuf();
      msg::RunManifest manifest;
      google::protobuf::util::JsonParseOptions options;
      options.ignore_unknown_fields = true;
      if (!google::protobuf::util::JsonStringToMessage(text.str(), &manifest, options).ok()) {
        throw std::runtime_error("manifest.json does not parse");
      }
      if (manifest.state() != "recording") continue;
      manifest.set_state("interrupted");
      manifest.set_ended_utc(utc_now("%Y-%m-%dT%H:%M:%SZ"));
      write_text(manifest_file, manifest_json(manifest));
      marked.push_back(entry.path());
    } catch (const std::exception& e) {
      if (problems) problems->push_back(entry.path().string() + ": " + e.what());
    }
  }
  return marked;
}

double frame_gap_s(const drivers::FramePair& pair) {
  if (pair.a.device_timestamp_ns != 0 && pair.b.device_timestamp_ns != 0) {
    return (double(pair.b.device_timestamp_ns) - double(pair.a.device_timestamp_ns)) * 1e-9;
  }
  return (double(pair.b.host_timestamp_ns) - double(pair.a.host_timestamp_ns)) * 1e-9;
}

Recorder::Recorder(const Setup& setup) : dir_(setup.data_dir / ("run-" + setup.run_id)) {
  std::error_code ec;
  fs::create_directories(setup.data_dir, ec);
  if (!fs::create_directory(dir_, ec)) {
    throw InputError("run folder " + dir_.string() + ": " +
                     (ec ? ec.message() : std::string("already exists")));
  }
  fs::create_directory(dir_ / "frames");
  fs::create_directory(dir_ / "vectors");
  manifest_.set_run_id(setup.run_id);
  manifest_.set_state("recording");
  manifest_.set_started_utc(utc_now("%Y-%m-%dT%H:%M:%SZ"));
  manifest_.set_camera_uri(setup.camera_uri);
  manifest_.set_trigger_uri(setup.trigger_uri);
  manifest_.set_camera_model(setup.camera_model);
  manifest_.set_camera_triggering(setup.camera_triggering);
  if (setup.config) {
    write_text(dir_ / "run.yaml", setup.config->text);
    manifest_.set_config_file("run.yaml");
    manifest_.set_nominal_dt_s(setup.config->dt_s);
    manifest_.set_rate_hz(setup.config->rate_hz);
    nominal_dt_s_ = setup.config->dt_s;
    write_text(dir_ / "process.yaml", setup.config->process_yaml());
    manifest_.set_process_file("process.yaml");
  }
  if (setup.calibration && !setup.calibration->nominal()) {
    const RunCalibration& c = *setup.calibration;
    write_text(dir_ / "calibration.h5", c.bytes);
    manifest_.set_calibration("file");
    manifest_.set_calibration_file("calibration.h5");
    manifest_.set_calibration_source(c.source.string());
    manifest_.set_calibration_bytes(c.bytes.size());
    manifest_.set_calibration_crc32(io::crc32_hex(c.crc32));
  } else {
    manifest_.set_calibration("nominal");
  }
  if (!setup.camera_file.empty()) {
    io::write_atomically(dir_ / "camera.yaml",
                         [&](const fs::path& tmp) { fs::copy_file(setup.camera_file, tmp); });
    manifest_.set_camera_file("camera.yaml");
  }
  std::lock_guard lock(mutex_);
  write_manifest_locked();
}

void Recorder::record_pair(const drivers::FramePair& pair) {
  const std::string name = pair_name(pair.pair_index);
  const std::string a = "frames/" + name + "-A.tif", b = "frames/" + name + "-B.tif";
  // Frames are written outside the lock (the output stage may be listing vectors meanwhile), both at
  // once: each waits for the disk to confirm its data (fsync), and the folder is flushed once for both.
  auto frame_b = std::async(std::launch::async, [&] { io::write_tiff(dir_ / b, pair.b.image, false); });
  try {
    io::write_tiff(dir_ / a, pair.a.image, false);
  } catch (...) {
    frame_b.wait();
    throw;
  }
  frame_b.get();
  io::sync_folder(dir_ / "frames");
  std::lock_guard lock(mutex_);
  msg::ManifestPair* p = manifest_.add_pairs();
  p->set_pair_index(pair.pair_index);
  p->set_trigger_index(pair.trigger_index);
  p->set_frame_a(a);
  p->set_frame_b(b);
  p->set_frame_id_a(pair.a.frame_id);
  p->set_frame_id_b(pair.b.frame_id);
  p->set_device_timestamp_a_ns(pair.a.device_timestamp_ns);
  p->set_device_timestamp_b_ns(pair.b.device_timestamp_ns);
  p->set_host_timestamp_a_ns(pair.a.host_timestamp_ns);
  p->set_host_timestamp_b_ns(pair.b.host_timestamp_ns);
  p->set_frame_gap_s(frame_gap_s(pair));
  p->set_nominal_dt_s(nominal_dt_s_);
  if (pair.measured) {
    p->set_measured_dt_s(pair.measured->dt_s());
    p->set_pulse1_ns(pair.measured->pulse1_ns);
    p->set_pulse2_ns(pair.measured->pulse2_ns);
  }
  write_manifest_locked();
}

void Recorder::record_vectors(std::uint64_t pair_index, const VectorField& field) {
  const std::string file = "vectors/" + pair_name(pair_index) + ".h5";
  io::write_vector_field_h5(dir_ / file, field);
  std::lock_guard lock(mutex_);
  statistics_.add(field);
  for (msg::ManifestPair& p : *manifest_.mutable_pairs()) {
    if (p.pair_index() == pair_index) p.set_vectors(file);
  }
  manifest_.set_pairs_processed(manifest_.pairs_processed() + 1);
  write_manifest_locked();
}

void Recorder::write_statistics_locked() {
  const Grid3& g = statistics_.grid();
  // The mean as a vector field: mean velocity times the nominal dt, so u, v, w read back as the
  // mean velocity; the fluctuations and sample counts beside it.
  VectorField mean(g);
  mean.dt_s = nominal_dt_s_ > 0 ? nominal_dt_s_ : 1.0;
  const double to_mm = mean.dt_s * 1e3;
  const std::array<std::vector<float>*, 3> d{&mean.dx_mm, &mean.dy_mm, &mean.dz_mm};
  for (int c = 0; c < 3; ++c) {
    const std::vector<float> m = statistics_.mean(c);
    for (std::size_t i = 0; i < m.size(); ++i) (*d[c])[i] = float(m[i] * to_mm);
  }
  std::vector<float> count(g.count());
  for (std::size_t i = 0; i < count.size(); ++i) {
    count[i] = float(statistics_.count()[i]);
    mean.valid[i] = statistics_.count()[i] > 0;
  }
  io::write_vector_field_h5(dir_ / "statistics.h5", mean,
                            {{"u_rms", statistics_.rms(0)},
                             {"v_rms", statistics_.rms(1)},
                             {"w_rms", statistics_.rms(2)},
                             {"count", count}});
  manifest_.set_statistics_file("statistics.h5");
}

void Recorder::record_drops(const std::vector<drivers::PairDrop>& drops) {
  std::lock_guard lock(mutex_);
  for (const drivers::PairDrop& d : drops) {
    if (manifest_.dropped_size() >= kMaxListedDrops) break;
    msg::ManifestDrop* out = manifest_.add_dropped();
    out->set_trigger_index(d.trigger_index);
    out->set_reason(drivers::to_string(d.reason));
  }
}

void Recorder::add_warning(const std::string& warning) {
  std::lock_guard lock(mutex_);
  for (const std::string& w : manifest_.warnings()) {
    if (w == warning) return;
  }
  manifest_.add_warnings(warning);
}

void Recorder::close(const std::string& state, std::uint64_t processed, std::uint64_t skipped,
                     const msg::Losses& losses, std::uint64_t frames_lost) {
  std::lock_guard lock(mutex_);
  if (closed_) return;
  closed_ = true;
  manifest_.set_state(state);
  manifest_.set_ended_utc(utc_now("%Y-%m-%dT%H:%M:%SZ"));
  manifest_.set_pairs_processed(processed);
  manifest_.set_pairs_skipped(skipped);
  *manifest_.mutable_losses() = losses;
  manifest_.set_frames_lost(frames_lost);
  // The final manifest goes first: statistics are a summary of files already listed, and a disk
  // that fills up writing them must not leave the folder "recording".
  write_manifest_locked();
  if (statistics_.fields() > 0) {
    write_statistics_locked();
    write_manifest_locked();
  }
}

std::uint64_t Recorder::pairs_recorded() const {
  std::lock_guard lock(mutex_);
  return std::uint64_t(manifest_.pairs_size());
}

msg::RunManifest Recorder::manifest() const {
  std::lock_guard lock(mutex_);
  return manifest_;
}

void Recorder::write_manifest_locked() { write_text(dir_ / "manifest.json", manifest_json(manifest_)); }

}  // namespace plenopiv::daemon
