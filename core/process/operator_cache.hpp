// Setup once per geometry: pair operators kept in the process (the daemon, run after run), their
// weight tables and depth responses kept on disk (the CLI, call after call), keyed by what they
// are built from.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/process/process.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::process {

class DepthResponse;  // depth_response.hpp

// What a weighting operator is built from, as bytes: the camera's optics and sensor, the lens
// centres, the white image's size and checksums, the grid, the angular sampling, and the
// operator's byte format. Two inputs with the same key give the same operator.
std::string operator_key(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white,
                         const Grid3& grid, double angular_sampling);

// What a cache's last lookup did: used its file (hit), or found none, one for another key or
// format (stale), a damaged one (corrupt), or could not write the one it made (unwritable).
enum class CacheOutcome { hit, missing, stale, corrupt, unwritable };
const char* cache_outcome_name(CacheOutcome o);

// Weight tables in files of a folder, one per key (weights-<hash of the key>.bin: a header with
// the full key, the payload's length and XXH3 checksum, then recon::WeightingOperator::serialize's
// bytes). A file is used only when its key, length and checksum all match and its bytes read
// back; a stale (other key or format) or damaged file is rebuilt and replaced, never trusted.
// Files are written atomically (io::write_atomically); the folder keeps the `keep` most recently
// used ones.
class WeightsDiskCache {
 public:
  // What the last weights() call did.
  using Outcome = CacheOutcome;
  static const char* name(Outcome o) { return cache_outcome_name(o); }

  explicit WeightsDiskCache(std::filesystem::path folder, std::size_t keep = 4);

  // The operator for these inputs: read from its file, or built and written there. `key`
  // (optional): operator_key of these very inputs, when the caller has it (hashing a large white
  // image is not free).
  std::unique_ptr<const recon::WeightingOperator> weights(const optics::CameraModel& camera,
                                                          const optics::MicrolensArray& lenses, const ImageF& white,
                                                          const Grid3& grid, double angular_sampling,
                                                          const std::string* key = nullptr);
  // weights() as a PairOperator's source of weights (this cache must outlive the call).
  PairOperator::WeightsSource source();
  Outcome last_outcome() const { return outcome_; }
  // One line for the user: which file, and why it was (not) used.
  const std::string& last_note() const { return note_; }
  std::filesystem::path file_for(const std::string& key) const;
  const std::filesystem::path& folder() const { return folder_; }

 private:
  std::filesystem::path folder_;
  std::size_t keep_;
  Outcome outcome_ = Outcome::missing;
  std::string note_;
};

// What a depth response (depth_response.hpp) is measured from, as bytes: the operator's inputs
// (`operator_key` of the camera in the frames' pixels, the lenses, the white image, the
// reconstruction grid and sampling), the camera the simulated pairs are rendered on, every
// processing setting (settings_key), and the running executable's build ID (any change of code
// measures anew). Empty when the executable has no build ID: such a response cannot be told from
// another build's and is not kept.
std::string depth_response_key(const std::string& operator_key, const optics::CameraModel& render_camera,
                               const ProcessSettings& settings);

// Depth responses in files of a folder (the weight tables' folder), one per key
// (depth-response-<hash of the key>.bin, with the weight files' header and checks): measuring one
// costs minutes at the paper's scale, reading it back next to nothing. A stale or damaged file is
// measured anew and replaced; the folder keeps the `keep` most recently used ones.
class DepthResponseDiskCache {
 public:
  explicit DepthResponseDiskCache(std::filesystem::path folder, std::size_t keep = 16);
  // The response kept for `key` (depth_response_key), else measure()'s, then kept for it.
  DepthResponse response(const std::string& key, const std::function<DepthResponse()>& measure);
  CacheOutcome last_outcome() const { return outcome_; }
  // One line for the user: which file, and why it was (not) used.
  const std::string& last_note() const { return note_; }
  std::filesystem::path file_for(const std::string& key) const;

 private:
  std::filesystem::path folder_;
  std::size_t keep_;
  CacheOutcome outcome_ = CacheOutcome::missing;
  std::string note_;
};

// The folder the CLI keeps weight tables in: $PLENOPIV_CACHE_DIR, else $XDG_CACHE_HOME/plenopiv,
// else $HOME/.cache/plenopiv; empty when none of them is set.
std::filesystem::path default_cache_folder();

// Pair operators kept in memory, the `capacity` most recently used, keyed by operator_key of the
// inputs they were built from: a daemon keeps one for its life, so that a run on the geometry of
// an earlier one starts without building tables. Optionally backed by a WeightsDiskCache for the
// operators it builds. Thread-safe; the operators are shared read-only.
class OperatorCache {
 public:
  explicit OperatorCache(std::size_t capacity = 2, std::filesystem::path disk_folder = {});

  // Where one get() took its operator from (for that call, whatever other threads do meanwhile).
  struct Provenance {
    std::string key;       // operator_key of the inputs
    std::string note;      // for the user, as last_note() says
    bool on_disk = false;  // its weight tables are in the disk folder (read from it, or written there)
  };

  // The operator for these inputs. `provenance` (optional): where it came from.
  std::shared_ptr<const PairOperator> get(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                                          const ImageF& white, const ProcessSettings& settings,
                                          Provenance* provenance = nullptr);
  std::shared_ptr<const PairOperator> get(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                                          const ImageF& white, const Grid3& grid, double angular_sampling,
                                          Provenance* provenance = nullptr);

  struct Counts {
    std::size_t hits = 0, builds = 0;
  };
  Counts counts() const;
  // Where the last get() took its operator from: "kept in memory", or the disk cache's note, or
  // "built".
  std::string last_note() const;
  // The folder of the disk cache; empty without one.
  std::filesystem::path disk_folder() const;

 private:
  std::size_t capacity_;
  std::unique_ptr<WeightsDiskCache> disk_;
  mutable std::mutex mutex_;
  struct Kept {
    std::string key;
    std::shared_ptr<const PairOperator> op;
    bool on_disk = false;
  };
  std::list<Kept> kept_;  // most recent first
  Counts counts_;
  std::string note_;
};

}  // namespace plenopiv::process
