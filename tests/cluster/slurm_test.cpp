// `plenopiv slurm` on a real one-node Slurm (scripts/slurm-local.sh: munged, slurmctld and slurmd
// on this machine, started for the test and stopped after it): a 4-shard array over a small
// recorded run and its merge job give the bits of a local reprocess; a failed task is resubmitted
// alone and the merge follows it; a depth response is measured once, by a setup job before the shards. Where the
// cluster cannot start, the test fails with the reason.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/base/grid.hpp"
#include "core/io/hdf5_files.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/recorded_run.hpp"
#include "tests/support/shallow_spec.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

class Slurm : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    cluster_dir() = testing_support::temp_dir("slurm") / "cluster";
    std::string out;
    const int rc = testing_support::run_command(
        {"/bin/bash", std::string(PLENOPIV_SOURCE_DIR) + "/scripts/slurm-local.sh", "start", cluster_dir().string()},
        out, 60s);
    start_output() = out;
    started() = rc == 0;
    ::setenv("SLURM_CONF", (cluster_dir() / "slurm.conf").c_str(), 1);
  }
  static void TearDownTestSuite() {
    std::string out;
    testing_support::run_command(
        {"/bin/bash", std::string(PLENOPIV_SOURCE_DIR) + "/scripts/slurm-local.sh", "stop", cluster_dir().string()},
        out, 30s);
  }
  void SetUp() override { ASSERT_TRUE(started()) << "the one-node Slurm did not start:\n" << start_output(); }

  static fs::path& cluster_dir() {
    static fs::path dir;
    return dir;
  }
  static std::string& start_output() {
    static std::string out;
    return out;
  }
  static bool& started() {
    static bool ok = false;
    return ok;
  }
};

std::string plenopiv_ok(const std::vector<std::string>& args) {
  std::vector<std::string> argv{testing_support::binary("plenopiv")};
  argv.insert(argv.end(), args.begin(), args.end());
  std::string out;
  EXPECT_EQ(testing_support::run_command(argv, out, 300s), 0) << out;
  return out;
}

// Waits until Slurm no longer lists any of `jobs` (they ran, failed or were cancelled).
void wait_for_jobs(const std::string& jobs) {
  std::string out;
  for (int i = 0; i < 600; ++i) {
    out.clear();
    const int rc = testing_support::run_command(
        {"/usr/bin/env", "squeue", "--noheader", "--jobs=" + jobs, "--format=%i %T %r"}, out);
    if (rc == 0 && out.empty()) return;
    if (rc != 0 && out.find("Invalid job id") != std::string::npos) return;
    std::this_thread::sleep_for(500ms);
  }
  FAIL() << "jobs " << jobs << " still queued after 5 minutes: " << out;
}

// "123 124\n" (what `slurm submit` prints) -> "123,124".
std::string job_list(const std::string& submit_stdout) {
  std::istringstream in(submit_stdout.substr(submit_stdout.rfind('\n', submit_stdout.size() - 2) + 1));
  std::string array, merge;
  in >> array >> merge;
  return array.empty() || merge.empty() ? merge : array + "," + merge;
}

std::string file_text(const fs::path& file) {
  std::ifstream in(file);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void expect_same_field(const fs::path& a, const fs::path& b) {
  ASSERT_TRUE(fs::exists(b)) << b;
  const VectorField fa = io::read_vector_field_h5(a), fb = io::read_vector_field_h5(b);
  EXPECT_EQ(fa.grid, fb.grid) << b;
  EXPECT_EQ(fa.dx_mm, fb.dx_mm) << b;
  EXPECT_EQ(fa.dy_mm, fb.dy_mm) << b;
  EXPECT_EQ(fa.dz_mm, fb.dz_mm) << b;
  EXPECT_EQ(fa.valid, fb.valid) << b;
  EXPECT_EQ(fa.dt_s, fb.dt_s) << b;
}

// Every pair's field and the run statistics of `cluster` are those of `local`, bit for bit.
void expect_same_outputs(const fs::path& local, const fs::path& cluster, int pairs) {
  for (int p = 0; p < pairs; ++p) {
    char name[32];
    std::snprintf(name, sizeof name, "pair-%06d.h5", p);
    expect_same_field(local / name, cluster / name);
  }
  expect_same_field(local / "statistics.h5", cluster / "statistics.h5");
  EXPECT_EQ(file_text(local / "series.pvd"), file_text(cluster / "series.pvd"));
}

// One small run of 8 pairs and its local reprocess, made once for the tests of this process.
const fs::path& recorded_run() {
  static const fs::path run = [] {
    const fs::path r = testing_support::record_small_run(testing_support::temp_dir("slurm") / "data",
                                                         testing_support::small_sim_uri(), {}, 8);
    plenopiv_ok({"process", "--run", r.string(), "-o", (r.parent_path() / "local").string()});
    return r;
  }();
  return run;
}

TEST_F(Slurm, FourShardsAndTheMergeGiveTheBitsOfALocalReprocess) {
  const fs::path& run = recorded_run();
  const fs::path out = run.parent_path() / "cluster";
  const std::string submitted =
      plenopiv_ok({"slurm", "submit", "--run", run.string(), "-o", out.string(), "--shards", "4", "--cpus", "1"});
  EXPECT_NE(submitted.find("8 pairs in 4 shards; 4 shard(s) to run: 0-3"), std::string::npos) << submitted;
  wait_for_jobs(job_list(submitted));
  const std::string status = plenopiv_ok({"slurm", "status", "--run", run.string(), "-o", out.string()});
  EXPECT_NE(status.find("pairs      8 of 8 have outputs"), std::string::npos) << status;
  EXPECT_NE(status.find("merge      done"), std::string::npos) << status << file_text(out / "slurm" / "merge.out");
  for (int shard = 0; shard < 4; ++shard) {
    const std::string log = file_text(out / "slurm" / ("shard-" + std::to_string(shard) + ".out"));
    EXPECT_NE(log.find("2 pair(s) selected, 2 processed"), std::string::npos) << "shard " << shard << ":\n" << log;
  }
  expect_same_outputs(run.parent_path() / "local", out, 8);
}

// A task that fails (its pair's output path is taken by a folder) leaves its shard incomplete; the
// merge waiting on it is cancelled; `submit --resume` sends that shard alone, which redoes only its
// missing pair, and the merge; the result is the local one.
TEST_F(Slurm, AFailedTaskIsResubmittedAloneAndTheMergeFollows) {
  const fs::path& run = recorded_run();
  const fs::path out = run.parent_path() / "retry";
  fs::create_directories(out / "pair-000003.h5");  // shard 1 of 4 holds pairs 2 and 3
  const std::string first =
      plenopiv_ok({"slurm", "submit", "--run", run.string(), "-o", out.string(), "--shards", "4", "--cpus", "1"});
  wait_for_jobs(job_list(first));
  std::string status = plenopiv_ok({"slurm", "status", "--run", run.string(), "-o", out.string()});
  EXPECT_NE(status.find("pairs      7 of 8 have outputs"), std::string::npos) << status;
  EXPECT_NE(status.find("shard 1    1/2  not in the queue: failed or cancelled"), std::string::npos) << status;
  EXPECT_NE(status.find("merge      not in the queue and not done"), std::string::npos) << status;
  EXPECT_NE(status.find("--resume   (resubmits the 1 incomplete shard(s))"), std::string::npos) << status;
  EXPECT_FALSE(fs::exists(out / "statistics.h5"));

  fs::remove(out / "pair-000003.h5");
  const std::string second = plenopiv_ok(
      {"slurm", "submit", "--run", run.string(), "-o", out.string(), "--shards", "4", "--cpus", "1", "--resume"});
  EXPECT_NE(second.find("1 shard(s) to run: 1;"), std::string::npos) << second;
  wait_for_jobs(job_list(second));
  const std::string log = file_text(out / "slurm" / "shard-1.out");
  EXPECT_NE(log.find("2 pair(s) selected, 1 processed, 1 up to date"), std::string::npos) << log;
  status = plenopiv_ok({"slurm", "status", "--run", run.string(), "-o", out.string()});
  EXPECT_NE(status.find("merge      done"), std::string::npos) << status << file_text(out / "slurm" / "merge.out");
  expect_same_outputs(run.parent_path() / "local", out, 8);
}

// Settings that measure MART's depth response: a setup job measures it once into the shared cache
// folder before the shards, which read it back instead of each measuring its own; the outputs are a
// local reprocess's with the same settings. (0.2 particles per microlens: a test's time, most of
// it the simulator's frames; the response's accuracy is tests/e2e/depth_response_test.cpp's.)
TEST_F(Slurm, ADepthResponseIsMeasuredOnceBySetupJobBeforeTheShards) {
  const fs::path& run = recorded_run();
  const fs::path spec = run.parent_path() / "with-depth-response.yaml";
  std::ofstream(spec) << "dt_s: 0.001" << testing_support::kShallowSmallBox
                      << "reconstruction: {iterations: 8, mu: 1, acceleration: nesterov, depth_response_ppm: 0.2}\n";
  const fs::path local = run.parent_path() / "local-depth-response";
  const std::string measured_locally =
      plenopiv_ok({"process", "--run", run.string(), "-c", spec.string(), "-o", local.string(), "--pairs", "0:4",
                   "--cache-dir", (run.parent_path() / "local-cache").string()});
  ASSERT_NE(measured_locally.find("depth response measured and kept in the cache"), std::string::npos)
      << measured_locally;

  const fs::path out = run.parent_path() / "depth-response";
  const fs::path cache = run.parent_path() / "shared-cache";
  const std::string submitted =
      plenopiv_ok({"slurm", "submit", "--run", run.string(), "-o", out.string(), "-c", spec.string(), "--pairs", "0:4",
                   "--shards", "2", "--cpus", "1", "--cache-dir", cache.string()});
  EXPECT_NE(submitted.find("setup job "), std::string::npos) << submitted;
  EXPECT_TRUE(fs::exists(out / "slurm" / "setup.sbatch"));
  wait_for_jobs(job_list(submitted));
  const std::string setup = file_text(out / "slurm" / "setup.out");
  EXPECT_NE(setup.find("depth response measured and kept in the cache: " + cache.string()), std::string::npos) << setup;
  EXPECT_NE(setup.find("prepared for 4 pair(s): the weight tables and the depth response"), std::string::npos) << setup;
  for (int shard = 0; shard < 2; ++shard) {
    const std::string log = file_text(out / "slurm" / ("shard-" + std::to_string(shard) + ".out"));
    EXPECT_NE(log.find("depth response from the cache: " + cache.string()), std::string::npos)
        << "shard " << shard << ":\n"
        << log;
    EXPECT_EQ(log.find("depth response measured"), std::string::npos) << "shard " << shard << ":\n" << log;
    EXPECT_NE(log.find("2 pair(s) selected, 2 processed"), std::string::npos) << "shard " << shard << ":\n" << log;
  }
  const std::string status =
      plenopiv_ok({"slurm", "status", "--run", run.string(), "-o", out.string(), "--pairs", "0:4"});
  EXPECT_NE(status.find("setup      job "), std::string::npos) << status;
  EXPECT_NE(status.find("merge      done"), std::string::npos) << status << file_text(out / "slurm" / "merge.out");
  expect_same_outputs(local, out, 4);
}

// Refusals before anything is queued: more shards than pairs, a folder that is not a run.
TEST_F(Slurm, BadSubmissionsAreRefusedBeforeAnythingIsQueued) {
  const fs::path& run = recorded_run();
  std::string out;
  EXPECT_EQ(testing_support::run_command({testing_support::binary("plenopiv"), "slurm", "submit", "--run", run.string(),
                                          "-o", (run.parent_path() / "many").string(), "--shards", "9"},
                                         out),
            2)
      << out;
  EXPECT_NE(out.find("--shards 9: only 8 pairs are selected"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(run.parent_path() / "many" / "slurm" / "jobs.yaml"));
  EXPECT_EQ(testing_support::run_command(
                {testing_support::binary("plenopiv"), "slurm", "submit", "--run", run.parent_path().string()}, out),
            2)
      << out;
  EXPECT_NE(out.find("manifest.json"), std::string::npos) << out;
}

}  // namespace
}  // namespace plenopiv
