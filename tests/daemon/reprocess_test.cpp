// A run recorded live (sim trigger + simulated camera + the plenoptic stage) and reprocessed from
// its folder alone with `plenopiv process --run`: the same fields, pair by pair; a damaged folder
// is refused naming what is missing.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <thread>

#include "core/io/hdf5_files.hpp"
#include "core/optics/camera_file.hpp"
#include "daemon/processing.hpp"
#include "daemon/run.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/sim/sim_camera.hpp"
#include "tests/support/child_process.hpp"
#include "tests/support/run_manifest.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::daemon {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

const std::string kCameraFile = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";

using testing_support::read_manifest;

// One short live run, recorded once for all tests of this file.
const fs::path& recorded_run() {
  static const fs::path dir = [] {
    const fs::path data = testing_support::temp_dir("reprocess") / "data";
    fs::remove_all(data);
    drivers::register_sim_camera(drivers::CameraRegistry::instance(), kCameraFile);
    RunStateMachine state;
    RunEnvironment env;
    env.data_dir = data;
    env.default_camera_uri = "sim://?seed=3&ppm=0.2&rays=500&dx_mm=0.25&flow_dt_us=1000";  // 0.25 mm in dt
    env.default_trigger_uri = "sim://";
    env.camera_file = kCameraFile;
    env.state = &state;
    env.processing = plenoptic_processing(optics::load_camera_file(kCameraFile));
    const RunConfig config = parse_run_config(
        "pairs: 3\nrate_hz: 2\ndt_s: 0.001\nmax_pairs_in_flight: 3\n"
        "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-0.5, 0.5], voxel_mm: 0.125}\n"
        "reconstruction: {iterations: 2, start: ones, dark_weight_cutoff: 0.99}\n"
        "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n",
        "run.yaml");
    state.start("r");
    Run run(config, "r", env);
    for (int i = 0; i < 3000 && !run.finished(); ++i) std::this_thread::sleep_for(10ms);
    EXPECT_TRUE(run.finished());
    EXPECT_EQ(state.state(), RunState::Idle) << state.error();
    return run.dir();
  }();
  return dir;
}

TEST(Reprocess, EveryPairComesBackAsTheLivePathRecordedIt) {
  const fs::path& run = recorded_run();
  const msg::RunManifest m = read_manifest(run);
  ASSERT_EQ(m.pairs_size(), 3);
  std::string out;
  const int status = testing_support::run_command(
      {testing_support::binary("plenopiv"), "process", "--run", run.string()}, out, 300s);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("process: 100%"), std::string::npos) << out;

  int compared = 0;
  for (const msg::ManifestPair& p : m.pairs()) {
    char name[32];
    std::snprintf(name, sizeof name, "pair-%06llu", static_cast<unsigned long long>(p.pair_index()));
    const fs::path again = run / "reprocessed" / (std::string(name) + ".h5");
    ASSERT_TRUE(fs::exists(again)) << again;
    EXPECT_TRUE(fs::exists(fs::path(again).replace_extension(".vti")));
    if (p.vectors().empty()) continue;  // skipped on the live path: nothing to compare with
    const VectorField live = io::read_vector_field_h5(run / p.vectors());
    const VectorField re = io::read_vector_field_h5(again);
    ASSERT_EQ(live.grid.shape, re.grid.shape);
    EXPECT_EQ(live.grid.origin_mm, re.grid.origin_mm);
    EXPECT_DOUBLE_EQ(live.dt_s, re.dt_s);  // the pair's measured dt, both times
    EXPECT_DOUBLE_EQ(re.dt_s, p.measured_dt_s());
    // Same settings, same frames, deterministic kernels: the same numbers, bit for bit.
    EXPECT_EQ(live.dx_mm, re.dx_mm) << name;
    EXPECT_EQ(live.dy_mm, re.dy_mm) << name;
    EXPECT_EQ(live.dz_mm, re.dz_mm) << name;
    EXPECT_EQ(live.valid, re.valid) << name;
    std::size_t valid = 0;
    for (auto v : re.valid) valid += v;
    EXPECT_GT(valid, 0u) << name;
    ++compared;
  }
  std::printf("reprocess: %d of %d pairs compared with the live fields\n", compared, m.pairs_size());
  EXPECT_GE(compared, 1);  // the live path may skip pairs when it falls behind; it kept up here
}

// Copies the run folder, spoils it with `damage`, and expects `process --run` to fail naming `culprit`.
void expect_refused(const std::string& label, const std::function<void(const fs::path&)>& damage,
                    const std::string& culprit) {
  const fs::path copy = testing_support::temp_dir("reprocess") / ("damaged-" + label);
  fs::remove_all(copy);
  fs::copy(recorded_run(), copy, fs::copy_options::recursive);
  fs::remove_all(copy / "reprocessed");
  damage(copy);
  std::string out;
  const int status = testing_support::run_command(
      {testing_support::binary("plenopiv"), "process", "--run", copy.string()}, out, 120s);
  EXPECT_NE(status, 0) << out;
  EXPECT_NE(out.find(culprit), std::string::npos) << "expected '" << culprit << "' in:\n" << out;
  EXPECT_FALSE(fs::exists(copy / "reprocessed")) << label;
}

TEST(Reprocess, ADamagedFolderIsRefusedNamingWhatIsMissing) {
  expect_refused("camera", [](const fs::path& d) { fs::remove(d / "camera.yaml"); }, "camera_file");
  expect_refused("settings", [](const fs::path& d) { fs::remove(d / "process.yaml"); }, "process.yaml is missing");
  expect_refused("frame", [](const fs::path& d) { fs::remove(d / "frames/pair-000001-B.tif"); },
                 "pairs[1].frame_b");
  expect_refused("manifest", [](const fs::path& d) { fs::remove(d / "manifest.json"); }, "manifest.json: missing");
  expect_refused("json", [](const fs::path& d) { std::ofstream(d / "manifest.json") << "{\"pairs\": 3"; },
                 "not a run manifest");
  expect_refused("key", [](const fs::path& d) {
    std::ifstream in(d / "manifest.json");
    std::stringstream text;
    text << in.rdbuf();
    std::string s = text.str();
    const auto at = s.find("\"process_file\": \"process.yaml\"");
    ASSERT_NE(at, std::string::npos);
    s.replace(at, std::string("\"process_file\": \"process.yaml\"").size(), "\"process_file\": \"\"");
    std::ofstream(d / "manifest.json") << s;
  }, "process_file is empty");
}

}  // namespace
}  // namespace plenopiv::daemon
