// Reprocessing a recorded run: offline settings, pair ranges, jobs in parallel, resume, shards for a
// cluster, and the merge (statistics and a ParaView series) that makes one result of them.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace plenopiv::client {

struct ReprocessOptions {
  std::filesystem::path run;     // the run folder (plenopivd's)
  std::filesystem::path output;  // default: <run>/reprocessed
  // The processing spec: empty or "run": the run's own process.yaml; else a spec file
  // (process.yaml's keys), for offline settings better than the live ones.
  std::string config;
  std::string tier = "full";  // "full", or "live" to reproduce the live lane's fast tier
  // Pair indices [first, last) of the run to process (default: all).
  std::optional<std::pair<std::uint64_t, std::uint64_t>> pairs;
  // This process does shard `first` of `second` (contiguous blocks of the selected pairs) and
  // leaves the merge to a later call with `merge_only`.
  std::optional<std::pair<int, int>> shard;
  int jobs = 1;             // pairs processed at once (they share the operator; each needs its buffers)
  bool resume = false;      // skip pairs whose output exists with the same input hash
  bool merge_only = false;  // only check the outputs and write statistics.h5 and series.pvd
  // Only check the inputs and make what the pairs share (the weight tables and, where the settings
  // ask for one, the depth response) in `weights_cache`, then stop: a cluster submission's first
  // job, so that its tasks read them instead of each making its own.
  bool prepare_only = false;
  // The folder that keeps weight tables between calls (process::OperatorCache over its files);
  // empty: the tables are built and kept nowhere.
  std::filesystem::path weights_cache;
};

// What happened, for the caller's summary line and for tests.
struct ReprocessReport {
  std::size_t selected = 0;     // pairs in range (and in the shard)
  std::size_t processed = 0;    // computed now
  std::size_t skipped = 0;      // up to date already (resume)
  bool merged = false;          // statistics.h5 and series.pvd written
  bool depth_response = false;  // the settings measure one (made or read from the cache)
  std::filesystem::path output;
};

// Checks everything first (the folder, its frames, the settings against the camera, memory for
// `jobs` pairs), then (unless `prepare_only`) processes the selected pairs with each pair's measured dt (the run's dt_s
// where none was measured) through one process::PairProcessor, writing <output>/pair-<n>.h5
// (with the inputs' hash) and .vti, with a progress bar over pairs. Without a shard it then merges
// (merge_outputs). InputError naming the culprit on bad input; nothing is written before the
// checks pass.
ReprocessReport reprocess_run(const ReprocessOptions& options);

// The merge: every selected pair's output must exist with the hash of its current inputs (else an
// InputError naming how many are missing and the first of them); writes <output>/statistics.h5
// (mean, RMS fluctuation, valid fraction per node, in pair order: the same bits however the pairs
// were computed) and <output>/series.pvd (ParaView: the pairs' .vti in time order).
ReprocessReport merge_outputs(const ReprocessOptions& options);

// Each of `shards` shards of the selected pairs (as --shard i/n splits them): its pairs and how many
// of them are done. `verify`: done means an output with the hash of its current inputs (reads every
// frame); else its .h5 and .vti are there (cheap: what a status display shows; tasks and the merge
// check the hashes).
struct ShardState {
  std::size_t pairs = 0, done = 0;
  bool complete() const { return done == pairs; }
};
struct ShardPlan {
  std::vector<ShardState> shards;
  double bytes_per_pair = 0;  // the estimated peak memory of one pair in flight
  // The settings measure MART's depth response before the first pair (process::PairProcessor):
  // minutes at paper scale, worth one job that keeps it for the others.
  bool depth_response = false;
  std::filesystem::path output;
  bool merged = false;  // statistics.h5 and series.pvd are there, newer than every pair's output
};
ShardPlan plan_shards(const ReprocessOptions& options, int shards, bool verify);

// "a:b", "a:", ":b" → [a, b); InputError naming `--pairs` otherwise.
std::pair<std::uint64_t, std::uint64_t> parse_pair_range(const std::string& text);
// "i/n" with 0 <= i < n → (i, n); InputError naming `--shard` otherwise.
std::pair<int, int> parse_shard(const std::string& text);

}  // namespace plenopiv::client
