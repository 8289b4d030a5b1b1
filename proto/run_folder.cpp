// The run folder: written by plenopivd as a run goes, read by `plenopiv process --run` and the
// cluster jobs; the one library that knows its layout and its manifest.
#include "proto/run_folder.hpp"

#include <fcntl.h>
#include <google/protobuf/util/json_util.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <future>
#include <memory>
#include <regex>
#include <set>
#include <sstream>
#include <system_error>

#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/tiff.hpp"
#include "core/process/field_file.hpp"
#include "proto/valid_text.hpp"

namespace plenopiv::run_folder {
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

void write_text(const fs::path& path, const std::string& text) {
  io::write_atomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw std::runtime_error("cannot write " + tmp.string());
  });
}

// The names of the 64-bit integer fields of the manifest's messages (protobuf's JSON mapping
// quotes them; the manifest writes them as numbers).
std::set<std::string> integer64_fields() {
  std::set<std::string> names;
  for (const google::protobuf::Descriptor* d : {msg::RunManifest::descriptor(), msg::ManifestPair::descriptor(),
                                                msg::ManifestDrop::descriptor(), msg::Losses::descriptor()}) {
    for (int i = 0; i < d->field_count(); ++i) {
      const auto type = d->field(i)->cpp_type();
      if (type == google::protobuf::FieldDescriptor::CPPTYPE_INT64 ||
          type == google::protobuf::FieldDescriptor::CPPTYPE_UINT64) {
        names.insert(d->field(i)->name());
      }
    }
  }
  return names;
}

constexpr const char* kJournal = "journal.jsonl";

// A message as protobuf JSON with proto field names, 64-bit integers as numbers (protobuf's JSON
// mapping quotes them; its parser takes either); `pretty`: indented, every field printed (the
// manifest), else one line of the fields that are set (a journal entry).
std::string message_json(const google::protobuf::Message& message, bool pretty) {
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = pretty;
  options.always_print_primitive_fields = pretty;
  options.preserve_proto_field_names = true;
  // A camera's model string or a warning quoting a path may hold bytes that are not UTF-8: printed
  // as they are, they make JSON that protobuf's reader refuses when the folder is read back.
  std::unique_ptr<google::protobuf::Message> valid(message.New());
  valid->CopyFrom(message);
  msg::make_text_valid_utf8(*valid);
  std::string json;
  const auto status = google::protobuf::util::MessageToJsonString(*valid, &json, options);
  if (!status.ok()) throw std::runtime_error("manifest: " + status.ToString());
  // "pair_index": "42" -> "pair_index": 42, for the 64-bit fields only (string fields keep their
  // quotes whatever they hold).
  static const std::set<std::string> fields = integer64_fields();
  static const std::regex quoted(R"re("([a-z0-9_]+)":( ?)"(-?[0-9]+)")re");
  std::string out;
  out.reserve(json.size());
  auto last = json.cbegin();
  for (std::sregex_iterator it(json.begin(), json.end(), quoted), end; it != end; ++it) {
    const std::smatch& m = *it;
    if (!fields.count(m[1].str())) continue;
    out.append(last, m[0].first);
    out += "\"" + m[1].str() + "\":" + m[2].str() + m[3].str();
    last = m[0].second;
  }
  out.append(last, json.cend());
  return out;
}

// Adds a journal entry to a manifest. A trigger is a recorded pair or listed dropped, never both:
// a camera lists a stray frame's loss against the trigger it infers from the frame's id, and a pair
// recorded for that trigger (before or after) shows that the trigger itself was not lost (the
// stray frame stays counted in the losses).
void apply_entry(msg::RunManifest& manifest, ManifestIndex& index, const msg::ManifestJournalEntry& entry) {
  if (entry.has_pair()) {
    const auto [it, fresh] = index.pair_position.try_emplace(entry.pair().pair_index(), manifest.pairs_size());
    if (fresh) {
      *manifest.add_pairs() = entry.pair();
      const std::uint64_t trigger = entry.pair().trigger_index();
      index.recorded_triggers.insert(trigger);
      if (index.dropped_triggers.erase(trigger)) {
        auto* dropped = manifest.mutable_dropped();
        dropped->erase(std::remove_if(dropped->begin(), dropped->end(),
                                      [&](const msg::ManifestDrop& d) { return d.trigger_index() == trigger; }),
                       dropped->end());
      }
    } else {
      manifest.mutable_pairs(it->second)->MergeFrom(entry.pair());
    }
  } else if (entry.has_drop()) {
    const std::uint64_t trigger = entry.drop().trigger_index();
    if (manifest.dropped_size() < Writer::kMaxListedDrops && !index.recorded_triggers.count(trigger)) {
      *manifest.add_dropped() = entry.drop();
      index.dropped_triggers.insert(trigger);
    }
  } else if (entry.has_warning()) {
    if (std::find(manifest.warnings().begin(), manifest.warnings().end(), entry.warning()) == manifest.warnings().end())
      manifest.add_warnings(entry.warning());
  }
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  if (!in) throw InputError(path.string() + ": cannot read");
  return text.str();
}

}  // namespace

std::string manifest_json(const msg::RunManifest& manifest) { return message_json(manifest, true); }

msg::RunManifest parse_manifest(const std::string& json, const std::string& source) {
  msg::RunManifest m;
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = true;  // a manifest from a newer version still reads
  if (const auto status = google::protobuf::util::JsonStringToMessage(json, &m, options); !status.ok()) {
    throw InputError(source + ": not a run manifest: " + std::string(status.message()));
  }
  return m;
}

msg::RunManifest read_manifest(const fs::path& run_dir) {
  const fs::path manifest_path = run_dir / "manifest.json";
  msg::RunManifest manifest = parse_manifest(read_text(manifest_path), manifest_path.string());
  const fs::path journal_path = run_dir / kJournal;
  // A closed run's manifest holds everything (its journal, left by a crash just before removal, too).
  if (manifest.state() != "recording" || !fs::exists(journal_path)) return manifest;
  const std::string journal = read_text(journal_path);
  ManifestIndex index;
  for (int i = 0; i < manifest.pairs_size(); ++i) {
    index.pair_position.emplace(manifest.pairs(i).pair_index(), i);
    index.recorded_triggers.insert(manifest.pairs(i).trigger_index());
  }
  for (const msg::ManifestDrop& d : manifest.dropped()) index.dropped_triggers.insert(d.trigger_index());
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = true;
  std::size_t start = 0;
  for (int line = 1;; ++line) {
    const std::size_t end = journal.find('\n', start);
    if (end == std::string::npos) break;  // the rest (if any) is a line a crash cut short
    msg::ManifestJournalEntry entry;
    const auto status =
        google::protobuf::util::JsonStringToMessage(journal.substr(start, end - start), &entry, options);
    if (!status.ok()) {
      throw InputError(journal_path.string() + ": line " + std::to_string(line) +
                       ": not a journal entry: " + std::string(status.message()));
    }
    apply_entry(manifest, index, entry);
    start = end + 1;
  }
  return manifest;
}

std::string new_run_id() { return utc_now("%Y%m%d-%H%M%S"); }

fs::path run_dir(const fs::path& data_dir, const std::string& run_id) {
  return data_dir / (std::string(kRunFolderPrefix) + run_id);
}

void write_statistics(const fs::path& path, const piv::RunningStatistics& statistics, double nominal_dt_s,
                      std::uint64_t fields) {
  const Grid3& g = statistics.grid();
  // The mean as a vector field: mean velocity times the nominal dt, so u, v, w read back as the
  // mean velocity; the fluctuations, sample counts and valid fraction beside it.
  VectorField mean(g);
  mean.dt_s = nominal_dt_s > 0 ? nominal_dt_s : 1.0;
  const double to_mm = mean.dt_s * 1e3;
  const std::array<std::vector<float>*, 3> d{&mean.dx_mm, &mean.dy_mm, &mean.dz_mm};
  for (int c = 0; c < 3; ++c) {
    const std::vector<float> m = statistics.mean(c);
    for (std::size_t i = 0; i < m.size(); ++i) (*d[c])[i] = float(m[i] * to_mm);
  }
  std::vector<float> count(g.count()), valid_fraction(g.count());
  for (std::size_t i = 0; i < count.size(); ++i) {
    count[i] = float(statistics.count()[i]);
    valid_fraction[i] = fields ? float(double(statistics.count()[i]) / double(fields)) : 0.f;
    mean.valid[i] = statistics.count()[i] > 0;
  }
  io::write_vector_field_h5(path, mean,
                            {{"u_rms", statistics.rms(0), "m/s"},
                             {"v_rms", statistics.rms(1), "m/s"},
                             {"w_rms", statistics.rms(2), "m/s"},
                             {"count", count, "1"},
                             {"valid_fraction", valid_fraction, "1"}},
                            {{"fields", std::to_string(fields) + " vector fields averaged"}});
}

std::string pair_name(std::uint64_t index) {
  char text[32];
  std::snprintf(text, sizeof text, "pair-%06llu", static_cast<unsigned long long>(index));
  return text;
}

std::vector<fs::path> mark_interrupted_runs(const fs::path& data_dir, std::vector<std::string>* problems) {
  std::vector<fs::path> marked;
  std::error_code ec;
  fs::directory_iterator it(data_dir, ec);
  if (ec) return marked;  // no data directory yet: nothing was interrupted
  for (const auto& entry : it) {
    const fs::path manifest_file = entry.path() / "manifest.json";
    if (!entry.path().filename().string().starts_with(kRunFolderPrefix) || !fs::is_regular_file(manifest_file, ec))
      continue;
    try {
      msg::RunManifest manifest = read_manifest(entry.path());
      const fs::path journal = entry.path() / kJournal;
      if (manifest.state() != "recording") {
        if (fs::remove(journal)) io::sync_folder(entry.path());  // closed, but stopped before removing it
        continue;
      }
      // The journal folded into the manifest, then removed: the folder stands on its manifest alone.
      manifest.set_state("interrupted");
      manifest.set_ended_utc(utc_now("%Y-%m-%dT%H:%M:%SZ"));
      write_text(manifest_file, manifest_json(manifest));
      if (fs::remove(journal)) io::sync_folder(entry.path());
      marked.push_back(entry.path());
    } catch (const std::exception& e) {
      if (problems) problems->push_back(entry.path().string() + ": " + e.what());
    }
  }
  return marked;
}

Writer::Writer(const Setup& setup) : dir_(run_dir(setup.data_dir, setup.run_id)) {
  std::error_code ec;
  fs::create_directories(setup.data_dir, ec);
  if (!fs::create_directory(dir_, ec)) {
    throw InputError("run folder " + dir_.string() + ": " + (ec ? ec.message() : std::string("already exists")));
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
  write_text(dir_ / "run.yaml", setup.run_yaml);
  manifest_.set_config_file("run.yaml");
  manifest_.set_nominal_dt_s(setup.nominal_dt_s);
  manifest_.set_rate_hz(setup.rate_hz);
  nominal_dt_s_ = setup.nominal_dt_s;
  write_text(dir_ / "process.yaml", setup.process_yaml);
  process_yaml_ = setup.process_yaml;
  manifest_.set_process_file("process.yaml");
  if (setup.calibration) {
    const CalibrationCopy& c = *setup.calibration;
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
    io::write_atomically(dir_ / "camera.yaml", [&](const fs::path& tmp) { fs::copy_file(setup.camera_file, tmp); });
    manifest_.set_camera_file("camera.yaml");
  }
  std::lock_guard lock(mutex_);
  write_manifest_locked();
  const fs::path journal = dir_ / kJournal;
  journal_fd_ = ::open(journal.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (journal_fd_ < 0) throw std::system_error(errno, std::generic_category(), "cannot create " + journal.string());
  io::sync_folder(dir_);
}

Writer::~Writer() {
  if (journal_fd_ >= 0) ::close(journal_fd_);
}

void Writer::journal_locked(const msg::ManifestJournalEntry& entry, bool sync) {
  if (journal_fd_ < 0) throw std::logic_error("run_folder::Writer: the run is closed");
  const std::string line = message_json(entry, false) + "\n";
  const fs::path journal = dir_ / kJournal;
  for (std::size_t done = 0; done < line.size();) {
    const ssize_t n = ::write(journal_fd_, line.data() + done, line.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw std::system_error(errno, std::generic_category(), "cannot append to " + journal.string());
    done += std::size_t(n);
  }
  if (sync && ::fdatasync(journal_fd_) != 0)
    throw std::system_error(errno, std::generic_category(), "cannot sync " + journal.string());
}

void Writer::record_pair(const PairRecord& pair) {
  if (!pair.frame_a || !pair.frame_b) throw std::logic_error("run_folder::Writer::record_pair: no frames");
  const std::string name = pair_name(pair.pair_index);
  const std::string a = "frames/" + name + "-A.tif", b = "frames/" + name + "-B.tif";
  // Frames are written outside the lock (the output stage may be listing vectors meanwhile), both at
  // once: each waits for the disk to confirm its data (fsync), and the folder is flushed once for both.
  auto frame_b =
      std::async(std::launch::async, [&] { io::write_tiff(dir_ / b, *pair.frame_b, false, pair.visit_rows_b); });
  try {
    io::write_tiff(dir_ / a, *pair.frame_a, false, pair.visit_rows_a);
  } catch (...) {
    frame_b.wait();
    throw;
  }
  frame_b.get();
  io::sync_folder(dir_ / "frames");
  std::lock_guard lock(mutex_);
  msg::ManifestJournalEntry entry;
  msg::ManifestPair* p = entry.mutable_pair();
  p->set_pair_index(pair.pair_index);
  p->set_trigger_index(pair.trigger_index);
  p->set_frame_a(a);
  p->set_frame_b(b);
  p->set_frame_id_a(pair.frame_id_a);
  p->set_frame_id_b(pair.frame_id_b);
  p->set_device_timestamp_a_ns(pair.device_timestamp_a_ns);
  p->set_device_timestamp_b_ns(pair.device_timestamp_b_ns);
  p->set_host_timestamp_a_ns(pair.host_timestamp_a_ns);
  p->set_host_timestamp_b_ns(pair.host_timestamp_b_ns);
  p->set_frame_gap_s(pair.frame_gap_s);
  p->set_nominal_dt_s(nominal_dt_s_);
  if (pair.laser_pulses_ns) {
    const auto [p1, p2] = *pair.laser_pulses_ns;
    p->set_measured_dt_s(double(p2 - p1) * 1e-9);
    p->set_pulse1_ns(p1);
    p->set_pulse2_ns(p2);
  }
  journal_locked(entry);
  apply_entry(manifest_, index_, entry);
}

void Writer::record_vectors(std::uint64_t pair_index, const VectorField& field, std::span<const std::uint8_t> flags,
                            process::Tier tier) {
  const bool live = tier == process::Tier::live;
  const std::string file = std::string(live ? "vectors/live/" : "vectors/") + pair_name(pair_index) + ".h5";
  std::string run_id, frame_a, frame_b;
  double measured_dt_s = 0;
  {
    std::lock_guard lock(mutex_);
    run_id = manifest_.run_id();
    if (const auto it = index_.pair_position.find(pair_index); it != index_.pair_position.end()) {
      const msg::ManifestPair& p = manifest_.pairs(it->second);
      frame_a = p.frame_a();
      frame_b = p.frame_b();
      measured_dt_s = p.measured_dt_s();
    }
  }
  const std::vector<io::TextAttribute> provenance{
      {"run", run_id},
      {"pair_index", std::to_string(pair_index)},
      {"frame_a", frame_a},
      {"frame_b", frame_b},
      {"settings", process_yaml_},
      {"tier", process::tier_name(tier)},
      {"dt_s", std::to_string(field.dt_s)},
      {"dt_source", measured_dt_s > 0 ? "measured (laser Q-switch sync)" : "nominal (the run's dt_s)"}};
  if (live) fs::create_directories(dir_ / "vectors/live");
  process::write_vector_field_files(dir_ / file, {}, field, flags, provenance);
  std::lock_guard lock(mutex_);
  (live ? live_statistics_ : statistics_).add(field);
  manifest_.set_pairs_processed(manifest_.pairs_processed() + 1);
  // Listed with its pair; a field of a pair this folder never recorded is kept but not listed (a
  // journal line for it would add a pair without frames).
  if (!index_.pair_position.count(pair_index)) return;
  msg::ManifestJournalEntry entry;
  entry.mutable_pair()->set_pair_index(pair_index);
  if (live) {
    entry.mutable_pair()->set_live_vectors(file);
  } else {
    entry.mutable_pair()->set_vectors(file);
  }
  journal_locked(entry);
  apply_entry(manifest_, index_, entry);
}

void Writer::write_statistics_locked() {
  if (statistics_.fields() > 0) {
    write_statistics(dir_ / "statistics.h5", statistics_, nominal_dt_s_, statistics_.fields());
    manifest_.set_statistics_file("statistics.h5");
  }
  if (live_statistics_.fields() > 0) {
    write_statistics(dir_ / "statistics-live.h5", live_statistics_, nominal_dt_s_, live_statistics_.fields());
    manifest_.set_live_statistics_file("statistics-live.h5");
  }
}

// Drops and warnings name no file: their journal lines reach the disk with the next pair's sync,
// so that a flood of drops does not slow the recording of the pairs that do come.
void Writer::record_drop(std::uint64_t trigger_index, const std::string& reason) {
  std::lock_guard lock(mutex_);
  if (manifest_.dropped_size() >= kMaxListedDrops) return;
  msg::ManifestJournalEntry entry;
  entry.mutable_drop()->set_trigger_index(trigger_index);
  entry.mutable_drop()->set_reason(reason);
  journal_locked(entry, false);
  apply_entry(manifest_, index_, entry);
}

void Writer::add_warning(const std::string& warning) {
  std::lock_guard lock(mutex_);
  for (const std::string& w : manifest_.warnings()) {
    if (w == warning) return;
  }
  msg::ManifestJournalEntry entry;
  entry.set_warning(warning);
  journal_locked(entry, false);
  apply_entry(manifest_, index_, entry);
}

void Writer::close(const std::string& state, std::uint64_t processed, std::uint64_t skipped, const msg::Losses& losses,
                   std::uint64_t frames_lost, const std::vector<msg::LaneCounters>& lanes) {
  std::lock_guard lock(mutex_);
  if (closed_) return;
  closed_ = true;
  manifest_.set_state(state);
  manifest_.set_ended_utc(utc_now("%Y-%m-%dT%H:%M:%SZ"));
  manifest_.set_pairs_processed(processed);
  manifest_.set_pairs_skipped(skipped);
  *manifest_.mutable_losses() = losses;
  manifest_.set_frames_lost(frames_lost);
  manifest_.clear_lanes();
  for (const msg::LaneCounters& lane : lanes) *manifest_.add_lanes() = lane;
  // The final manifest goes first: statistics are a summary of files already listed, and a disk
  // that fills up writing them must not leave the folder "recording". The journal goes once the
  // manifest holds all it says (a crash in between leaves it beside a closed manifest: ignored).
  write_manifest_locked();
  ::close(journal_fd_);
  journal_fd_ = -1;
  if (fs::remove(dir_ / kJournal)) io::sync_folder(dir_);
  if (statistics_.fields() > 0 || live_statistics_.fields() > 0) {
    write_statistics_locked();
    write_manifest_locked();
  }
}

std::uint64_t Writer::pairs_recorded() const {
  std::lock_guard lock(mutex_);
  return std::uint64_t(manifest_.pairs_size());
}

msg::RunManifest Writer::manifest() const {
  std::lock_guard lock(mutex_);
  return manifest_;
}

void Writer::write_manifest_locked() { write_text(dir_ / "manifest.json", manifest_json(manifest_)); }

Reader::Reader(const fs::path& dir) : dir_(dir) {
  if (!fs::is_directory(dir_)) throw InputError("--run: " + dir_.string() + " is not a folder");
  const fs::path manifest_path = dir_ / "manifest.json";
  if (!fs::is_regular_file(manifest_path))
    throw InputError(manifest_path.string() + ": missing (not a plenopivd run folder?)");
  manifest_ = read_manifest(dir_);
  file("process_file", manifest_.process_file());
  file("camera_file", manifest_.camera_file());
  if (manifest_.calibration() == "file") {
    // The run's own copy, checked against what the daemon recorded when it copied it.
    calibration_ = file("calibration_file", manifest_.calibration_file());
    const std::string bytes = io::read_file_bytes(*calibration_);
    const std::string crc = io::crc32_hex(io::crc32_of(bytes));
    if (bytes.size() != manifest_.calibration_bytes() || crc != manifest_.calibration_crc32()) {
      throw InputError(calibration_->string() + ": " + std::to_string(bytes.size()) + " bytes, crc32 " + crc +
                       "; the manifest recorded " + std::to_string(manifest_.calibration_bytes()) + " bytes, crc32 " +
                       manifest_.calibration_crc32() + " (the copy was changed or damaged)");
    }
  } else if (manifest_.calibration() != "nominal") {
    throw InputError(manifest_path.string() + ": calibration: '" + manifest_.calibration() +
                     "' is not one this version can reprocess with (nominal, file)");
  }
  if (manifest_.pairs_size() == 0) throw InputError(manifest_path.string() + ": pairs: the run recorded no pair");
  std::set<std::uint64_t> indices;
  std::set<std::string> names;
  for (const msg::ManifestPair& p : manifest_.pairs()) {
    const std::string where = "pairs[" + std::to_string(p.pair_index()) + "]";
    if (!indices.insert(p.pair_index()).second) {
      throw InputError(manifest_path.string() + ": " + where + ": pair index listed twice");
    }
    PairEntry e;
    e.pair_index = p.pair_index();
    e.trigger_index = p.trigger_index();
    for (const auto& [key, name, out] :
         {std::tuple{".frame_a", &p.frame_a(), &e.frame_a}, std::tuple{".frame_b", &p.frame_b(), &e.frame_b}}) {
      *out = file(where + key, *name);
      if (!names.insert(fs::path(*name).lexically_normal().string()).second) {
        throw InputError(manifest_path.string() + ": " + where + key + ": " + *name + " is listed twice");
      }
    }
    if (p.measured_dt_s() > 0) e.measured_dt_s = p.measured_dt_s();
    e.vectors = p.vectors();
    e.live_vectors = p.live_vectors();
    pairs_.push_back(std::move(e));
  }
}

fs::path Reader::file(const std::string& key, const std::string& name) const {
  const fs::path manifest = dir_ / "manifest.json";
  if (name.empty())
    throw InputError(manifest.string() + ": " + key + " is empty: the run folder does not say where it is");
  // Every file a manifest names lies inside the folder: relative, never through "..".
  const fs::path rel(name);
  if (rel.is_absolute() || std::any_of(rel.begin(), rel.end(), [](const fs::path& part) { return part == ".."; })) {
    throw InputError(manifest.string() + ": " + key + ": '" + name + "' is not a path inside the run folder");
  }
  const fs::path path = dir_ / name;
  if (!fs::is_regular_file(path))
    throw InputError(manifest.string() + ": " + key + ": " + path.string() + " is missing");
  return path;
}

fs::path Reader::process_file() const { return dir_ / manifest_.process_file(); }
fs::path Reader::camera_file() const { return dir_ / manifest_.camera_file(); }

void Reader::check_frames(int width, int height) const {
  for (const PairEntry& p : pairs_) {
    for (const fs::path& frame : {p.frame_a, p.frame_b}) {
      const io::TiffInfo info = io::check_tiff(frame);
      if (info.width != width || info.height != height) {
        throw InputError(frame.string() + ": frame is " + std::to_string(info.width) + " x " +
                         std::to_string(info.height) + ", the run's camera (" + camera_file().string() + ") is " +
                         std::to_string(width) + " x " + std::to_string(height));
      }
    }
  }
}

}  // namespace plenopiv::run_folder
