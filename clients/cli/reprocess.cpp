// Reprocessing a recorded run: offline settings, pair ranges, jobs in parallel, resume, shards for a
// cluster, and the merge (statistics and a ParaView series) that makes one result of them.
#include "clients/cli/reprocess.hpp"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "clients/cli/progress.hpp"
#include "clients/cli/weights_cache.hpp"
#include "core/base/errors.hpp"
#include "core/base/memory.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"
#include "core/io/vtk_files.hpp"
#include "core/optics/camera_file.hpp"
#include "core/piv/statistics.hpp"
#include "core/process/field_file.hpp"
#include "core/process/frame_check.hpp"
#include "core/process/pair_processor.hpp"
#include "proto/run_folder.hpp"

namespace plenopiv::client {
namespace fs = std::filesystem;
namespace {

// Everything about a run that every pair of it shares, read and checked once.
struct RunInputs {
  run_folder::Reader reader;
  optics::CameraModel camera;
  std::string settings_text;  // the spec file's bytes: part of every pair's input hash
  std::string tier;
  process::ProcessSettings settings;
  std::string camera_crc, calibration_crc;
  std::vector<const run_folder::PairEntry*> selected;
  fs::path output;
};

process::ProcessSettings tier_of(const process::ProcessSpec& spec, const std::string& tier, const std::string& source) {
  if (tier == "full") return spec.full;
  if (tier == "live") {
    if (!spec.live) throw InputError(source + ": has no live: section (--tier live)");
    return *spec.live;
  }
  throw InputError("--tier: 'full' or 'live', got '" + tier + "'");
}

// Shard i of n of the selected pairs (in pair order): a contiguous block, the blocks' sizes within
// one of each other. Empty when there are more shards than pairs.
std::vector<const run_folder::PairEntry*> shard_of(const std::vector<const run_folder::PairEntry*>& pairs, int i,
                                                   int n) {
  const std::size_t begin = pairs.size() * std::size_t(i) / std::size_t(n);
  const std::size_t end = pairs.size() * std::size_t(i + 1) / std::size_t(n);
  return {pairs.begin() + std::ptrdiff_t(begin), pairs.begin() + std::ptrdiff_t(end)};
}

RunInputs read_inputs(const ReprocessOptions& o) {
  run_folder::Reader reader(o.run);
  optics::CameraModel camera = optics::load_camera_file(reader.camera_file());
  RunInputs in{std::move(reader), std::move(camera), {}, {}, {}, {}, {}, {}, {}};
  const fs::path spec_file = o.config.empty() || o.config == "run" ? in.reader.process_file() : fs::path(o.config);
  in.settings_text = io::read_file_bytes(spec_file);
  in.tier = o.tier;
  in.settings = tier_of(process::load_process_spec(spec_file), o.tier, spec_file.string());
  in.camera_crc = io::crc32_hex(io::checksum_of_file(in.reader.camera_file()).crc32);
  in.calibration_crc = in.reader.calibration_file() ? in.reader.manifest().calibration_crc32() : "nominal";
  in.reader.check_frames(in.camera.sensor().width_px, in.camera.sensor().height_px);

  std::vector<const run_folder::PairEntry*> in_range;
  for (const run_folder::PairEntry& p : in.reader.pairs()) {
    if (!o.pairs || (p.pair_index >= o.pairs->first && p.pair_index < o.pairs->second)) in_range.push_back(&p);
  }
  std::sort(in_range.begin(), in_range.end(), [](auto* a, auto* b) { return a->pair_index < b->pair_index; });
  if (in_range.empty()) throw InputError("--pairs: no recorded pair of " + o.run.string() + " is in that range");
  in.selected = o.shard ? shard_of(in_range, o.shard->first, o.shard->second) : in_range;
  in.output = o.output.empty() ? o.run / "reprocessed" : o.output;
  return in;
}

// What a pair's result depends on, one line each: this program's version, the CRC-32 of the
// settings text and tier, the camera file, the calibration, the pair's frames, and the dt it is
// processed with. Its CRC-32 is the input hash: an output whose hash matches is up to date.
std::string input_description(const RunInputs& in, const run_folder::PairEntry& p, double dt_s) {
  char dt[64];
  std::snprintf(dt, sizeof dt, "%.17g", dt_s);
  const std::string description = std::string("plenopiv ") + PLENOPIV_VERSION + "\nsettings " +
                                  io::crc32_hex(io::crc32_of(in.settings_text)) + " tier " + in.tier + "\ncamera " +
                                  in.camera_crc + "\ncalibration " + in.calibration_crc + "\nframe A " +
                                  io::crc32_hex(io::checksum_of_file(p.frame_a).crc32) + "\nframe B " +
                                  io::crc32_hex(io::checksum_of_file(p.frame_b).crc32) + "\ndt_s " + dt + "\n";
  return description;
}

std::string input_hash(const RunInputs& in, const run_folder::PairEntry& p, double dt_s) {
  return io::crc32_hex(io::crc32_of(input_description(in, p, dt_s)));
}

fs::path output_of(const RunInputs& in, const run_folder::PairEntry& p, const char* extension) {
  return in.output / (run_folder::pair_name(p.pair_index) + extension);
}

bool up_to_date(const RunInputs& in, const run_folder::PairEntry& p, const std::string& hash) {
  return fs::exists(output_of(in, p, ".vti")) && io::read_provenance(output_of(in, p, ".h5"), "input_hash") == hash;
}

// A progress bar several threads update (one pair's fraction each).
class SharedProgress {
 public:
  SharedProgress(std::size_t pairs) : progress_("process", "pairs", double(pairs)), pairs_(double(pairs)) {}
  void pair_progress(std::size_t slot, double fraction) {
    std::lock_guard lock(mutex_);
    if (slot >= current_.size()) current_.resize(slot + 1, 0.0);
    current_[slot] = fraction;
    report();
  }
  void pair_done(std::size_t slot) {
    std::lock_guard lock(mutex_);
    done_ += 1;
    if (slot < current_.size()) current_[slot] = 0;
    report();
  }

 private:
  void report() {
    double sum = done_;
    for (double f : current_) sum += f;
    progress_.update(std::min(1.0, sum / pairs_));
  }
  std::mutex mutex_;
  Progress progress_;
  double pairs_;
  double done_ = 0;
  std::vector<double> current_;
};

}  // namespace

std::pair<std::uint64_t, std::uint64_t> parse_pair_range(const std::string& text) {
  const auto colon = text.find(':');
  const auto number = [&](const std::string& part, std::uint64_t fallback) -> std::uint64_t {
    if (part.empty()) return fallback;
    if (part.find_first_not_of("0123456789") != std::string::npos || part.size() > 18) {
      throw InputError("--pairs: '" + text + "': give a:b (pair indices, b excluded), a: or :b");
    }
    return std::stoull(part);
  };
  if (colon == std::string::npos)
    throw InputError("--pairs: '" + text + "': give a:b (pair indices, b excluded), a: or :b");
  const std::uint64_t a = number(text.substr(0, colon), 0);
  const std::uint64_t b = number(text.substr(colon + 1), UINT64_MAX);
  if (!(a < b)) throw InputError("--pairs: '" + text + "': the first index must be below the second");
  return {a, b};
}

std::pair<int, int> parse_shard(const std::string& text) {
  const auto slash = text.find('/');
  const auto digits = [](const std::string& s) {
    return !s.empty() && s.size() <= 6 && s.find_first_not_of("0123456789") == std::string::npos;
  };
  if (slash == std::string::npos || !digits(text.substr(0, slash)) || !digits(text.substr(slash + 1))) {
    throw InputError("--shard: '" + text + "': give i/n, this task's shard i of n (0 <= i < n)");
  }
  const int i = std::stoi(text.substr(0, slash)), n = std::stoi(text.substr(slash + 1));
  if (n < 1 || i >= n) throw InputError("--shard: '" + text + "': needs 0 <= i < n");
  return {i, n};
}

ReprocessReport reprocess_run(const ReprocessOptions& o) {
  if (o.jobs < 1 || o.jobs > 64) throw InputError("--jobs: 1 to 64 pairs at once, got " + std::to_string(o.jobs));
  if (o.merge_only) return merge_outputs(o);
  if (o.prepare_only && o.weights_cache.empty())
    throw InputError(
        "--prepare makes the weight tables and depth response for later calls: it needs the cache "
        "(not --no-cache)");
  // Every input is read and checked before any long work starts or any file is written.
  const RunInputs in = read_inputs(o);
  const Grid3 g = in.settings.reconstruction_grid();
  const double per_pair = in.settings.peak_bytes_per_pair();
  require_memory(per_pair * o.jobs, "--jobs " + std::to_string(o.jobs) + ": " + std::to_string(o.jobs) +
                                        " pairs at once on a " + std::to_string(g.shape[0]) + " x " +
                                        std::to_string(g.shape[1]) + " x " + std::to_string(g.shape[2]) +
                                        " voxel volume");
  const calib::LoadedCalibration calibration = in.reader.calibration_file()
                                                   ? calib::load_calibration(*in.reader.calibration_file(), in.camera)
                                                   : calib::nominal_calibration(in.camera);
  fs::create_directories(in.output);
  std::fprintf(
      stderr,
      "%s: %zu pair(s)%s; volume %d x %d x %d voxels (+%d guard slices each depth end), about %.2f GB per pair "
      "in flight, %d at once; weights ...\n",
      o.run.string().c_str(), in.selected.size(),
      o.shard ? (" (shard " + std::to_string(o.shard->first) + "/" + std::to_string(o.shard->second) + ")").c_str()
              : "",
      in.settings.grid.shape[0], in.settings.grid.shape[1], in.settings.grid.shape[2], in.settings.guard_slices(),
      per_pair / 1e9, o.jobs);
  std::optional<process::OperatorCache> operators;
  if (!o.weights_cache.empty()) operators.emplace(1, o.weights_cache);
  const auto processor = make_pair_processor(in.camera, calibration, in.settings, operators ? &*operators : nullptr);
  ReprocessReport report;
  report.selected = in.selected.size();
  report.output = in.output;
  report.depth_response = processor->depth_response() != nullptr;
  if (o.prepare_only) {
    // What --prepare made is for the calls after it: a folder that could not keep it fails the call
    // (the setup note says why) rather than leave each later call to make its own.
    if (!processor->setup_on_disk())
      throw InputError("--prepare: the cache folder " + o.weights_cache.string() +
                       " did not keep what was made: " + processor->setup_note());
    return report;
  }
  // The settings the outputs were made with, beside them.
  io::write_text_atomically(in.output / "process.yaml", in.settings_text);

  SharedProgress progress(in.selected.size());
  std::atomic<std::size_t> next{0}, processed{0}, skipped{0};
  std::mutex errors_mutex;
  std::exception_ptr error;
  std::vector<std::string> warnings;
  const auto worker = [&](std::size_t slot) {
    for (;;) {
      {
        std::lock_guard lock(errors_mutex);
        if (error) return;
      }
      const std::size_t k = next++;
      if (k >= in.selected.size()) return;
      const run_folder::PairEntry& p = *in.selected[k];
      try {
        const double dt = process::pair_dt_s(in.settings, p.measured_dt_s);
        const std::string description = input_description(in, p, dt);
        const std::string hash = io::crc32_hex(io::crc32_of(description));
        if (o.resume && up_to_date(in, p, hash)) {
          ++skipped;
          progress.pair_done(slot);
          continue;
        }
        const ImageU16 a = io::read_tiff_u16(p.frame_a), b = io::read_tiff_u16(p.frame_b);
        for (const auto& [frame, name] : {std::pair{&a, "frame A"}, std::pair{&b, "frame B"}}) {
          if (const auto problem = process::frame_problem(frame->pixels)) {
            std::lock_guard lock(errors_mutex);
            warnings.push_back("pair " + std::to_string(p.pair_index) + " " + name + " " + *problem);
          }
        }
        process::PairOptions options;
        options.measured_dt_s = p.measured_dt_s;
        options.progress = [&](const std::string&, double f) { progress.pair_progress(slot, f); };
        const process::PairResult r = processor->process(a, b, options);
        char black_levels[512];  // as `plenopiv process` records it
        std::snprintf(black_levels, sizeof black_levels, "%s; frame A %s, frame B %s counts",
                      processor->black_level_note().c_str(), r.black_level_a.text().c_str(),
                      r.black_level_b.text().c_str());
        process::write_vector_field_files(
            output_of(in, p, ".h5"), output_of(in, p, ".vti"), r.correlation.field, r.correlation.flags,
            {{"input_hash", hash},
             {"inputs", description},
             {"run", o.run.string()},
             {"pair_index", std::to_string(p.pair_index)},
             {"dt_source", p.measured_dt_s ? "measured (laser Q-switch sync)" : "nominal (dt_s)"},
             {"black_level", black_levels},
             {"settings", in.settings_text},
             {"tier", in.tier}});
        ++processed;
        progress.pair_done(slot);
      } catch (...) {
        std::lock_guard lock(errors_mutex);
        if (!error) error = std::current_exception();
        return;
      }
    }
  };
  std::vector<std::thread> threads;
  for (int j = 1; j < o.jobs; ++j) threads.emplace_back(worker, std::size_t(j));
  worker(0);
  for (std::thread& t : threads) t.join();
  if (error) std::rethrow_exception(error);
  for (const std::string& w : warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  report.processed = processed;
  report.skipped = skipped;
  if (!o.shard) {
    const ReprocessReport merged = merge_outputs(o);
    report.merged = merged.merged;
  }
  return report;
}

ReprocessReport merge_outputs(const ReprocessOptions& o) {
  ReprocessOptions all = o;
  all.shard.reset();  // the merge covers every selected pair, whatever shard called it
  const RunInputs in = read_inputs(all);
  std::vector<const run_folder::PairEntry*> missing;
  for (const run_folder::PairEntry* p : in.selected) {
    if (!up_to_date(in, *p, input_hash(in, *p, process::pair_dt_s(in.settings, p->measured_dt_s))))
      missing.push_back(p);
  }
  if (!missing.empty()) {
    throw InputError(in.output.string() + ": " + std::to_string(missing.size()) + " of " +
                     std::to_string(in.selected.size()) + " pairs have no up-to-date result (first: pair " +
                     std::to_string(missing.front()->pair_index) +
                     "): process them first (plenopiv process --run ... --resume, or resubmit their shards)");
  }
  piv::RunningStatistics statistics;
  std::vector<io::SeriesEntry> series;
  const std::uint64_t t0 = in.reader.manifest().pairs_size() ? in.reader.manifest().pairs(0).host_timestamp_a_ns() : 0;
  for (const run_folder::PairEntry* p : in.selected) {
    statistics.add(io::read_vector_field_h5(output_of(in, *p, ".h5")));
    std::uint64_t t = t0;
    for (const msg::ManifestPair& mp : in.reader.manifest().pairs()) {
      if (mp.pair_index() == p->pair_index) t = mp.host_timestamp_a_ns();
    }
    series.push_back({double(std::int64_t(t - t0)) * 1e-9, output_of(in, *p, ".vti").filename().string()});
  }
  run_folder::write_statistics(in.output / "statistics.h5", statistics, in.settings.correlation.dt_s,
                               statistics.fields());
  io::write_vtk_series(in.output / "series.pvd", series);
  ReprocessReport report;
  report.selected = in.selected.size();
  report.merged = true;
  report.output = in.output;
  return report;
}

ShardPlan plan_shards(const ReprocessOptions& o, int shards, bool verify) {
  if (shards < 1) throw InputError("--shards: at least 1, got " + std::to_string(shards));
  ReprocessOptions all = o;
  all.shard.reset();
  const RunInputs in = read_inputs(all);
  ShardPlan plan;
  plan.output = in.output;
  plan.bytes_per_pair = in.settings.peak_bytes_per_pair();
  plan.depth_response = in.settings.depth_response_ppm > 0;
  fs::file_time_type newest_pair = fs::file_time_type::min();
  bool all_there = true;
  for (int i = 0; i < shards; ++i) {
    ShardState s;
    for (const run_folder::PairEntry* p : shard_of(in.selected, i, shards)) {
      s.pairs += 1;
      const fs::path h5 = output_of(in, *p, ".h5"), vti = output_of(in, *p, ".vti");
      const bool there = fs::exists(h5) && fs::exists(vti);
      if (there) newest_pair = std::max(newest_pair, fs::last_write_time(h5));
      all_there = all_there && there;
      const bool done =
          verify ? up_to_date(in, *p, input_hash(in, *p, process::pair_dt_s(in.settings, p->measured_dt_s))) : there;
      s.done += done ? 1 : 0;
    }
    plan.shards.push_back(s);
  }
  const fs::path statistics = in.output / "statistics.h5", series = in.output / "series.pvd";
  plan.merged =
      all_there && fs::exists(statistics) && fs::exists(series) && fs::last_write_time(statistics) >= newest_pair;
  return plan;
}

}  // namespace plenopiv::client
