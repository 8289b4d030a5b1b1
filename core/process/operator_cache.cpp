// Pair operators kept in memory and weight tables kept on disk, keyed by what they are built from.
#include "core/process/operator_cache.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <optional>
#include <system_error>
#include <vector>

#include <xxhash.h>

#include "core/base/build_info.hpp"
#include "core/base/byte_stream.hpp"
#include "core/base/errors.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/depth_response.hpp"

namespace plenopiv::process {
namespace {

constexpr char kMagic[8] = {'P', 'L', 'W', 'C', 'A', 'C', 'H', 'E'};
// 2: the tables' checksum is XXH3's 64 bits (1: CRC-32); a file of another format is stale.
constexpr std::uint32_t kFileFormat = 2;

// XXH3 (xxHash's 64-bit hash) of `bytes`: the cache's file names and its tables' checksum.
std::uint64_t xxh3_of(std::string_view bytes) { return XXH3_64bits(bytes.data(), bytes.size()); }

std::string hex64(std::uint64_t v) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(v));
  return text;
}

// The file's header: magic, format, key, payload length and checksum; then the payload.
std::string header(const std::string& key, std::string_view payload) {
  std::string out(kMagic, sizeof kMagic);
  ByteWriter w(out);
  w.pod(kFileFormat);
  w.pod(std::uint64_t(key.size()));
  out += key;
  w.pod(std::uint64_t(payload.size()));
  w.pod(xxh3_of(payload));
  return out;
}

// Reads a file written with header(): the payload, or why it cannot be used (stale: another key
// or format; corrupt: truncated, wrong length or checksum).
struct Parsed {
  std::string_view payload;
  CacheOutcome problem = CacheOutcome::hit;
  std::string why;
};
Parsed parse(std::string_view file, const std::string& key) {
  using Outcome = CacheOutcome;
  auto bad = [](Outcome o, std::string why) { return Parsed{{}, o, std::move(why)}; };
  std::size_t at = 0;
  auto take = [&](std::size_t n) -> std::string_view {
    if (n > file.size() - at) return {};
    const std::string_view v = file.substr(at, n);
    at += n;
    return v;
  };
  auto take_u64 = [&](std::uint64_t& v) {
    const std::string_view b = take(sizeof v);
    if (b.size() != sizeof v) return false;
    std::memcpy(&v, b.data(), sizeof v);
    return true;
  };
  const std::string_view magic = take(sizeof kMagic);
  if (magic.size() != sizeof kMagic || std::memcmp(magic.data(), kMagic, sizeof kMagic) != 0)
    return bad(Outcome::corrupt, "not a plenopiv cache file");
  std::uint32_t format = 0;
  const std::string_view f = take(sizeof format);
  if (f.size() != sizeof format) return bad(Outcome::corrupt, "truncated");
  std::memcpy(&format, f.data(), sizeof format);
  if (format != kFileFormat) return bad(Outcome::stale, "written by another version");
  std::uint64_t key_size = 0, payload_size = 0;
  if (!take_u64(key_size) || key_size > file.size()) return bad(Outcome::corrupt, "truncated");
  const std::string_view stored_key = take(std::size_t(key_size));
  if (stored_key.size() != key_size) return bad(Outcome::corrupt, "truncated");
  if (stored_key != key) return bad(Outcome::stale, "made for another camera, calibration, volume or settings");
  std::uint64_t checksum = 0;
  if (!take_u64(payload_size) || !take_u64(checksum)) return bad(Outcome::corrupt, "truncated");
  const std::string_view payload = file.substr(at);
  if (payload.size() != payload_size)
    return bad(Outcome::corrupt, "holds " + std::to_string(payload.size()) + " bytes of contents, its header says " +
                                     std::to_string(payload_size));
  if (xxh3_of(payload) != checksum) return bad(Outcome::corrupt, "checksum does not match its contents");
  return Parsed{payload, Outcome::hit, {}};
}

// Keeps the `keep` most recently used <prefix>*.bin files of `folder`.
void trim(const std::filesystem::path& folder, const std::string& prefix, std::size_t keep) {
  std::error_code ec;
  std::vector<std::pair<std::filesystem::file_time_type, std::filesystem::path>> files;
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) != 0 || entry.path().extension() != ".bin") continue;
    files.emplace_back(std::filesystem::last_write_time(entry.path(), ec), entry.path());
  }
  if (files.size() <= keep) return;
  std::sort(files.begin(), files.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  for (std::size_t i = keep; i < files.size(); ++i) std::filesystem::remove(files[i].second, ec);
}

// A cache file mapped and checked against `key`: its payload when `outcome` is hit, else why not.
// Mapped, not read: a payload is copied once, from the page cache into its object. Cache files
// are replaced by rename and trimmed by removal, never truncated, so the mapping stays whole while
// another process writes the same key.
struct Loaded {
  std::optional<io::MappedFile> bytes;
  std::string_view payload;
  CacheOutcome outcome = CacheOutcome::missing;
  std::string why = "no file yet";
};
void load(const std::filesystem::path& file, const std::string& key, Loaded& l) {
  std::error_code ec;
  if (!std::filesystem::exists(file, ec)) return;
  try {
    l.bytes.emplace(file);
  } catch (const InputError& e) {
    l.outcome = CacheOutcome::corrupt;
    l.why = e.what();
    return;
  }
  const Parsed p = parse(l.bytes->bytes(), key);
  l.outcome = p.problem;
  l.why = p.why;
  l.payload = p.payload;
}

// Marks `file` as just used (trim() keeps the most recently used).
void touch(const std::filesystem::path& file) {
  std::error_code ec;
  std::filesystem::last_write_time(file, std::filesystem::file_time_type::clock::now(), ec);
}

// Writes `payload` under `key` to `file` atomically and trims the folder's <prefix> files to
// `keep`; throws what the file system does.
void store(const std::filesystem::path& file, const std::string& key, std::string_view payload,
           const std::string& prefix, std::size_t keep) {
  std::filesystem::create_directories(file.parent_path());
  const std::string head = header(key, payload);
  io::write_atomically(file, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(head.data(), std::streamsize(head.size()));
    out.write(payload.data(), std::streamsize(payload.size()));
    out.close();
    if (!out) throw InputError(tmp.string() + ": cannot write");
  });
  trim(file.parent_path(), prefix, keep);
}

std::string file_name(const std::string& prefix, const std::string& key) {
  return prefix + hex64(xxh3_of(key)) + ".bin";
}

// What a cache keeps in one file: its name in notes ("weight tables"), how it is made when not
// kept ("built", "measured"), and the folder's file prefix and count to keep.
struct Kind {
  const char* what;
  const char* made;
  const char* prefix;
  std::size_t keep;
};

// The object kept in `file` for `key` (read(payload), which throws InputError on bad bytes), else
// make()'s, then written there (write(object, payload)). `outcome` and `note` say which and why.
template <typename Read, typename Make, typename Write>
auto read_or_make(const Kind& kind, const std::filesystem::path& file, const std::string& key, Read&& read, Make&& make,
                  Write&& write, CacheOutcome& outcome, std::string& note) {
  Loaded loaded;
  load(file, key, loaded);
  if (loaded.outcome == CacheOutcome::hit) {
    try {
      auto kept = read(loaded.payload);
      touch(file);
      outcome = CacheOutcome::hit;
      note = std::string(kind.what) + " from the cache: " + file.string();
      return kept;
    } catch (const InputError& e) {
      loaded.outcome = CacheOutcome::corrupt;
      loaded.why = e.what();
    }
  }
  loaded.bytes.reset();
  outcome = loaded.outcome;
  auto made = make();
  try {
    std::string payload;
    write(made, payload);
    store(file, key, payload, kind.prefix, kind.keep);
    note = std::string(kind.what) + " " + kind.made + " and kept in the cache: " + file.string() +
           (loaded.outcome == CacheOutcome::missing
                ? ""
                : std::string(" (replaced: ") + cache_outcome_name(loaded.outcome) + ", " + loaded.why + ")");
  } catch (const std::exception& e) {
    outcome = CacheOutcome::unwritable;
    note = std::string(kind.what) + " " + kind.made + ", not kept in the cache (" + e.what() + ")";
  }
  return made;
}

constexpr const char* kWeightsPrefix = "weights-";
constexpr const char* kDepthResponsePrefix = "depth-response-";

}  // namespace

std::string operator_key(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white,
                         const Grid3& grid, double angular_sampling) {
  std::string key = "plenopiv weighting operator\n";
  ByteWriter w(key);
  w.pod(recon::WeightingOperator::kBytesFormat);
  const optics::CameraSpec& c = camera.spec();
  for (const int v :
       {c.sensor.width_px, c.sensor.height_px, c.microlens.count_x, c.microlens.count_y, int(c.microlens.layout)})
    w.pod(v);
  for (const double v :
       {c.sensor.pixel_pitch_mm, c.microlens.pitch_mm, c.microlens.focal_length_mm, c.main_lens.focal_length_mm,
        c.main_lens.f_number, c.main_lens.magnification, camera.image_distance_mm(), camera.object_distance_mm(),
        camera.aperture_diameter_mm(), camera.microlens_image_diameter_px(), camera.optical_axis_px()[0],
        camera.optical_axis_px()[1]})
    w.pod(v);
  const optics::Lattice& l = lenses.lattice;
  for (const int v : {int(l.layout), l.count_x, l.count_y}) w.pod(v);
  for (const double v : {l.pitch_x_mm, l.pitch_y_mm, l.rotation_rad, l.offset_x_mm, l.offset_y_mm}) w.pod(v);
  w.vec(lenses.centres_mm);
  const std::string_view white_bytes(reinterpret_cast<const char*>(white.pixels.data()),
                                     white.pixels.size() * sizeof(float));
  w.pod(white.width);
  w.pod(white.height);
  const XXH128_hash_t white_hash = XXH3_128bits(white_bytes.data(), white_bytes.size());
  w.pod(white_hash.low64);
  w.pod(white_hash.high64);
  w.pod(grid.shape);
  w.pod(grid.origin_mm);
  w.pod(grid.spacing_mm);
  w.pod(angular_sampling);
  return key;
}

const char* cache_outcome_name(CacheOutcome o) {
  switch (o) {
    case CacheOutcome::hit:
      return "hit";
    case CacheOutcome::missing:
      return "missing";
    case CacheOutcome::stale:
      return "stale";
    case CacheOutcome::corrupt:
      return "corrupt";
    case CacheOutcome::unwritable:
      return "unwritable";
  }
  return "?";
}

WeightsDiskCache::WeightsDiskCache(std::filesystem::path folder, std::size_t keep)
    : folder_(std::move(folder)), keep_(std::max<std::size_t>(keep, 1)) {}

std::filesystem::path WeightsDiskCache::file_for(const std::string& key) const {
  return folder_ / file_name(kWeightsPrefix, key);
}

std::unique_ptr<const recon::WeightingOperator> WeightsDiskCache::weights(const optics::CameraModel& camera,
                                                                          const optics::MicrolensArray& lenses,
                                                                          const ImageF& white, const Grid3& grid,
                                                                          double angular_sampling,
                                                                          const std::string* known_key) {
  const std::string key = known_key ? *known_key : operator_key(camera, lenses, white, grid, angular_sampling);
  return read_or_make(
      Kind{"weight tables", "built", kWeightsPrefix, keep_}, file_for(key), key,
      [](std::string_view payload) {
        return std::make_unique<const recon::WeightingOperator>(recon::WeightingOperator::deserialize(payload));
      },
      [&] { return std::make_unique<const recon::WeightingOperator>(camera, lenses, grid, white, angular_sampling); },
      [](const auto& op, std::string& payload) { op->serialize(payload); }, outcome_, note_);
}

std::string depth_response_key(const std::string& operator_key, const optics::CameraModel& render_camera,
                               const ProcessSettings& settings) {
  const std::string& build = executable_build_id();
  if (build.empty()) return {};
  std::string key =
      "plenopiv depth response\nbuild " + build + "\nrendered on\n" + optics::to_yaml(render_camera.spec()) + "\n";
  ByteWriter(key).pod(std::uint64_t(operator_key.size()));
  key += operator_key;
  key += settings_key(settings);
  return key;
}

DepthResponseDiskCache::DepthResponseDiskCache(std::filesystem::path folder, std::size_t keep)
    : folder_(std::move(folder)), keep_(std::max<std::size_t>(keep, 1)) {}

std::filesystem::path DepthResponseDiskCache::file_for(const std::string& key) const {
  return folder_ / file_name(kDepthResponsePrefix, key);
}

DepthResponse DepthResponseDiskCache::response(const std::string& key, const std::function<DepthResponse()>& measure) {
  return read_or_make(
      Kind{"depth response", "measured", kDepthResponsePrefix, keep_}, file_for(key), key,
      [](std::string_view payload) { return DepthResponse::deserialize(payload); }, measure,
      [](const DepthResponse& r, std::string& payload) { r.serialize(payload); }, outcome_, note_);
}

PairOperator::WeightsSource WeightsDiskCache::source() {
  return [this](const optics::CameraModel& c, const optics::MicrolensArray& l, const ImageF& w, const Grid3& g,
                double a) { return weights(c, l, w, g, a); };
}

std::filesystem::path default_cache_folder() {
  if (const char* dir = std::getenv("PLENOPIV_CACHE_DIR"); dir && *dir) return dir;
  if (const char* dir = std::getenv("XDG_CACHE_HOME"); dir && *dir) return std::filesystem::path(dir) / "plenopiv";
  if (const char* home = std::getenv("HOME"); home && *home) return std::filesystem::path(home) / ".cache" / "plenopiv";
  return {};
}

OperatorCache::OperatorCache(std::size_t capacity, std::filesystem::path disk_folder)
    : capacity_(std::max<std::size_t>(capacity, 1)) {
  if (!disk_folder.empty()) disk_ = std::make_unique<WeightsDiskCache>(std::move(disk_folder));
}

std::shared_ptr<const PairOperator> OperatorCache::get(const optics::CameraModel& camera,
                                                       const optics::MicrolensArray& lenses, const ImageF& white,
                                                       const ProcessSettings& settings, Provenance* provenance) {
  return get(camera, lenses, white, settings.reconstruction_grid(), settings.angular_sampling, provenance);
}

std::shared_ptr<const PairOperator> OperatorCache::get(const optics::CameraModel& camera,
                                                       const optics::MicrolensArray& lenses, const ImageF& white,
                                                       const Grid3& grid, double angular_sampling,
                                                       Provenance* provenance) {
  std::string key = operator_key(camera, lenses, white, grid, angular_sampling);
  std::lock_guard lock(mutex_);
  const auto tell = [&](const Kept& kept) {
    if (provenance) *provenance = Provenance{kept.key, note_, kept.on_disk};
    return kept.op;
  };
  for (auto it = kept_.begin(); it != kept_.end(); ++it) {
    if (it->key != key) continue;
    kept_.splice(kept_.begin(), kept_, it);
    ++counts_.hits;
    note_ = "operator kept in memory";
    return tell(kept_.front());
  }
  // The disk cache is asked for the inputs keyed above, as they are, or for a resampled lattice's.
  PairOperator::WeightsSource source;
  if (disk_)
    source = [&](const optics::CameraModel& c, const optics::MicrolensArray& l, const ImageF& w, const Grid3& g,
                 double a) {
      const bool keyed = &c == &camera && &l == &lenses && &w == &white && g == grid && a == angular_sampling;
      return disk_->weights(c, l, w, g, a, keyed ? &key : nullptr);
    };
  auto op = std::make_shared<const PairOperator>(camera, lenses, white, grid, angular_sampling, source);
  ++counts_.builds;
  note_ = disk_ ? disk_->last_note() : "operator built";
  const bool on_disk = disk_ && disk_->last_outcome() != CacheOutcome::unwritable;
  kept_.push_front(Kept{std::move(key), std::move(op), on_disk});
  if (kept_.size() > capacity_) kept_.pop_back();
  return tell(kept_.front());
}

std::filesystem::path OperatorCache::disk_folder() const { return disk_ ? disk_->folder() : std::filesystem::path(); }

OperatorCache::Counts OperatorCache::counts() const {
  std::lock_guard lock(mutex_);
  return counts_;
}

std::string OperatorCache::last_note() const {
  std::lock_guard lock(mutex_);
  return note_;
}

}  // namespace plenopiv::process
