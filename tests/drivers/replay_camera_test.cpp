// The replay camera `replay://`: conformance, recorded pixels bit for bit from TIFF and run
// folders, the free-running rate, triggers, the end of a recording, and refused URIs, folders and
// sizes.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "core/base/errors.hpp"
#include "core/io/tiff.hpp"
#include "drivers/camera/frame_pool.hpp"
#include "drivers/replay/replay_camera.hpp"
#include "proto/run_folder.hpp"
#include "tests/drivers/camera_conformance.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::drivers {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// 850 x 850 px: a pair is 2.9 MB of decoded frames.
const fs::path kCamera = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config/camera-small.yaml";
constexpr int kSide = 850;

// Frame `k` of a recording: a pattern no other frame has, over the full 16 bits.
ImageU16 frame_image(int k, int width = kSide, int height = kSide) {
  ImageU16 image(width, height);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    image.pixels[i] = std::uint16_t((i * 2654435761u + std::size_t(k) * 40503u) >> 7);
  }
  return image;
}

// The scratch folder the replay camera may read (its replay_dir).
fs::path replay_root() {
  static const fs::path root = testing_support::temp_dir("replay") / "root";
  fs::create_directories(root);
  return root;
}

// A folder of `pairs` pairs named pair-<k>-A.tif / pair-<k>-B.tif; frame 2k is A, 2k+1 is B.
fs::path tiff_folder(const std::string& name, int pairs, int width = kSide) {
  const fs::path dir = replay_root() / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (int k = 0; k < pairs; ++k) {
    io::write_tiff(dir / ("pair-" + std::to_string(k) + "-A.tif"), frame_image(2 * k, width), false);
    io::write_tiff(dir / ("pair-" + std::to_string(k) + "-B.tif"), frame_image(2 * k + 1, width), false);
  }
  return dir;
}

std::unique_ptr<Camera> open(const std::string& uri, const fs::path& camera_file = kCamera) {
  return open_replay_camera(DeviceUri::parse(uri), ReplaySource{replay_root(), camera_file});
}

void start(Camera& camera, TriggerSource source = TriggerSource::Software) {
  camera.configure(CameraSettings{});
  camera.arm(DoubleExposureSettings{source, 0.0});
  camera.start();
}

// Fires software triggers until `n` pairs came (a trigger whose pair was not decoded in time
// delivers nothing, and the recording goes on at the next one).
std::vector<FramePair> take_pairs(Camera& camera, int n) {
  std::vector<FramePair> out;
  for (int attempts = 0; int(out.size()) < n && attempts < 10 * n; ++attempts) {
    camera.software_trigger();
    if (auto p = camera.next_pair(500ms)) out.push_back(std::move(*p));
  }
  return out;
}

TEST(ReplayCamera, PassesTheConformanceSuite) {
  tiff_folder("conformance", 4);
  auto camera = open("replay://conformance?loop=1");
  testing_support::ConformanceOptions o;
  o.pairs_per_run = 5;  // more than recorded: the loop plays it again
  o.runs = 3;
  testing_support::check_camera_conformance(*camera, o);
  EXPECT_EQ(camera->info().sensor_width_px, kSide);
  EXPECT_EQ(camera->info().model, "replay camera");
}

// The recording fits buffer_mb (preloaded) or does not (read ahead, two pairs at a time): either
// way every pair is the recorded one, in order, and the loop starts again at the first.
TEST(ReplayCamera, ATiffFolderIsReplayedBitForBitInNameOrder) {
  tiff_folder("tiffs", 4);
  for (const std::string buffer : {"1024", "6"}) {
    SCOPED_TRACE("buffer_mb=" + buffer);
    auto camera = open("replay://tiffs?loop=1&buffer_mb=" + buffer);
    start(*camera);
    const std::vector<FramePair> pairs = take_pairs(*camera, 6);
    ASSERT_EQ(pairs.size(), 6u) << testing_support::describe(camera->counters());
    for (int i = 0; i < 6; ++i) {
      const int k = i % 4;
      EXPECT_EQ(pairs[i].a.image.pixels, frame_image(2 * k).pixels) << "pair " << i;
      EXPECT_EQ(pairs[i].b.image.pixels, frame_image(2 * k + 1).pixels) << "pair " << i;
      EXPECT_EQ(pairs[i].a.bit_depth, 16);
      EXPECT_EQ(pairs[i].b.frame_id, pairs[i].a.frame_id + 1);
      EXPECT_EQ(pairs[i].b.device_timestamp_ns, pairs[i].a.device_timestamp_ns + 1000);
    }
    std::printf("buffer_mb=%s: %s\n", buffer.c_str(), testing_support::describe(camera->counters()).c_str());
    camera->stop();
  }
}

// A consumer that lets go of a pair gives its buffers back (share_pair): the next frames are copied
// (preloaded) or decoded (read ahead) into them, and every frame is still the recorded one, with
// nothing of the frame before it.
TEST(ReplayCamera, ItsFramesReuseTheBuffersOfPairsLetGo) {
  tiff_folder("pooled", 3);
  for (const auto& [buffer, min_reused] : {std::pair{"1024", 10u}, std::pair{"6", 6u}}) {
    SCOPED_TRACE(std::string("buffer_mb=") + buffer);
    auto camera = open(std::string("replay://pooled?loop=1&buffer_mb=") + buffer);
    ASSERT_NE(camera->frame_pool(), nullptr);
    start(*camera);
    for (int i = 0; i < 7; ++i) {
      std::vector<FramePair> taken = take_pairs(*camera, 1);
      ASSERT_EQ(taken.size(), 1u) << testing_support::describe(camera->counters());
      const std::shared_ptr<const FramePair> pair = share_pair(std::move(taken[0]), camera->frame_pool());
      EXPECT_EQ(pair->a.image.pixels, frame_image(2 * (i % 3)).pixels) << "pair " << i;
      EXPECT_EQ(pair->b.image.pixels, frame_image(2 * (i % 3) + 1).pixels) << "pair " << i;
    }
    camera->stop();
    const FramePool::Counts c = camera->frame_pool()->counts();
    std::printf("buffer_mb=%s: %llu of %llu frames in reused buffers\n", buffer,
                static_cast<unsigned long long>(c.reused), static_cast<unsigned long long>(c.taken));
    // The first frames are fresh, and so are those decoded ahead of the consumer (read ahead: two
    // pairs) before a pair was let go.
    EXPECT_GE(c.reused, min_reused);
  }
}

// Opening reads the TIFF headers only (plenopivd opens the camera while answering `run start`): a
// recording that fits buffer_mb is decoded at start(), on the run's thread, so a frame replaced
// between open and start is played as it is at start.
TEST(ReplayCamera, ARecordingThatFitsIsDecodedAtStartNotAtOpen) {
  const fs::path dir = tiff_folder("decoded-at-start", 2);
  auto camera = open("replay://decoded-at-start");
  io::write_tiff(dir / "pair-1-A.tif", frame_image(99), false);
  start(*camera);
  const std::vector<FramePair> pairs = take_pairs(*camera, 2);
  ASSERT_EQ(pairs.size(), 2u) << testing_support::describe(camera->counters());
  EXPECT_EQ(pairs[0].a.image.pixels, frame_image(0).pixels);
  EXPECT_EQ(pairs[1].a.image.pixels, frame_image(99).pixels);
  camera->stop();
}

TEST(ReplayCamera, ARunFolderIsReplayedBitForBitInTheManifestsOrder) {
  const fs::path data = replay_root() / "runs";
  fs::remove_all(data);
  run_folder::Writer::Setup s;
  s.data_dir = data;
  s.run_id = "recorded";
  s.run_yaml = "dt_s: 0.001\n";
  s.process_yaml = "dt_s: 0.001\n";
  s.nominal_dt_s = 1e-3;
  s.rate_hz = 10;
  s.camera_uri = "sim://";
  s.trigger_uri = "sim://";
  s.camera_file = kCamera;
  s.camera_model = "simulated plenoptic camera";
  s.camera_triggering = "software";
  run_folder::Writer writer(s);
  std::vector<ImageU16> frames;
  for (int k = 0; k < 3; ++k) {
    frames.push_back(frame_image(100 + 2 * k));
    frames.push_back(frame_image(101 + 2 * k));
    run_folder::PairRecord r;
    r.pair_index = r.trigger_index = std::uint64_t(k);
    r.frame_a = &frames[frames.size() - 2];
    r.frame_b = &frames.back();
    r.frame_id_a = 2 * k + 1;
    r.frame_id_b = 2 * k + 2;
    writer.record_pair(r);
  }
  writer.close("complete", 0, 0);
  frames.clear();

  auto camera = open("replay://runs/" + writer.dir().filename().string());
  EXPECT_EQ(camera->info().serial, writer.dir().filename().string());
  start(*camera);
  const std::vector<FramePair> pairs = take_pairs(*camera, 3);
  ASSERT_EQ(pairs.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(pairs[k].a.image.pixels, frame_image(100 + 2 * k).pixels) << "pair " << k;
    EXPECT_EQ(pairs[k].b.image.pixels, frame_image(101 + 2 * k).pixels) << "pair " << k;
    EXPECT_EQ(pairs[k].trigger_index, std::uint64_t(k));
  }
  camera->stop();
}

// Free-running at rate_hz: the device clock ticks exactly 1/rate_hz apart; the host clock shows
// the rate within a loose sanity bound (the machine is shared).
TEST(ReplayCamera, FreeRunningPlaysAtRateHz) {
  tiff_folder("rate", 3);
  auto camera = open("replay://rate?rate_hz=20&loop=1");
  EXPECT_EQ(camera->trigger_input(), nullptr) << "a free-running camera has no trigger input";
  start(*camera);
  std::vector<FramePair> pairs;
  while (pairs.size() < 21) {
    auto p = camera->next_pair(2s);
    ASSERT_TRUE(p) << testing_support::describe(camera->counters());
    pairs.push_back(std::move(*p));
  }
  camera->stop();
  for (std::size_t i = 1; i < pairs.size(); ++i) {
    EXPECT_EQ(pairs[i].a.device_timestamp_ns - pairs[i - 1].a.device_timestamp_ns, 50'000'000u);
    EXPECT_EQ(pairs[i].trigger_index, pairs[i - 1].trigger_index + 1);
  }
  const double host_s = double(pairs.back().a.host_timestamp_ns - pairs.front().a.host_timestamp_ns) * 1e-9;
  const double rate = double(pairs.size() - 1) / host_s;
  std::printf("free-running at rate_hz=20: %.2f Hz on the host clock over %zu pairs\n", rate, pairs.size());
  EXPECT_GT(rate, 10.0) << "measured " << rate << " Hz";
  EXPECT_LT(rate, 40.0) << "measured " << rate << " Hz";
  EXPECT_EQ(camera->counters().frames_lost, 0u);
  // Software triggers are ignored while free-running, as a free-running camera ignores its line.
  camera->start();
  camera->software_trigger();
  camera->stop();
}

TEST(ReplayCamera, ItsTriggerInputPlaysAPairPerRisingEdgeWhenArmedExternal) {
  tiff_folder("edges", 2);
  auto camera = open("replay://edges");
  TriggerInput* input = camera->trigger_input();
  ASSERT_NE(input, nullptr);
  start(*camera, TriggerSource::External);
  input->rising_edge();
  auto p = camera->next_pair(2s);
  ASSERT_TRUE(p);
  EXPECT_EQ(p->a.image.pixels, frame_image(0).pixels);
  camera->stop();
  // Armed Software, edges are ignored.
  camera->arm(DoubleExposureSettings{TriggerSource::Software, 0.0});
  camera->start();
  input->rising_edge();
  EXPECT_FALSE(camera->next_pair(300ms));
  camera->stop();
}

TEST(ReplayCamera, TheEndOfARecordingWithoutLoopIsNamed) {
  tiff_folder("short", 2);
  auto triggered = open("replay://short");
  start(*triggered);
  EXPECT_EQ(take_pairs(*triggered, 2).size(), 2u);
  triggered->software_trigger();
  EXPECT_FALSE(triggered->next_pair(500ms));
  const CameraStatus s = triggered->status();
  EXPECT_TRUE(s.failed);
  EXPECT_NE(s.last_error.find("end of the recording: all 2 pairs played"), std::string::npos) << s.last_error;

  // Free-running, the acquisition just ends after the last pair.
  auto free = open("replay://short?rate_hz=50");
  start(*free);
  EXPECT_TRUE(free->next_pair(2s));
  EXPECT_TRUE(free->next_pair(2s));
  EXPECT_FALSE(free->next_pair(300ms));
  EXPECT_FALSE(free->status().failed);
  free->stop();
  EXPECT_EQ(free->counters().pairs_delivered, 2u);
}

std::string refusal(const std::string& uri, const fs::path& camera_file = kCamera,
                    const fs::path& root = replay_root()) {
  try {
    open_replay_camera(DeviceUri::parse(uri), ReplaySource{root, camera_file});
  } catch (const InputError& e) {
    return e.what();
  }
  return "(accepted)";
}

void expect_refused(const std::string& uri, const std::string& words, const fs::path& camera_file = kCamera,
                    const fs::path& root = replay_root()) {
  const std::string m = refusal(uri, camera_file, root);
  EXPECT_NE(m.find(uri), std::string::npos) << uri << ": " << m;
  EXPECT_NE(m.find(words), std::string::npos) << uri << ": " << m;
}

TEST(ReplayCamera, BadUrisFoldersAndFramesAreRefusedByName) {
  tiff_folder("good", 1);
  expect_refused("replay://good?speed=2", "speed");
  expect_refused("replay://good?rate_hz=-1", "rate_hz");
  expect_refused("replay://good?loop=2", "loop");
  expect_refused("replay://good?buffer_mb=0", "buffer_mb");
  expect_refused("replay://good?buffer_mb=1", "fewer than two pairs");
  expect_refused("replay://missing", "missing");
  expect_refused("replay://good", "no replay_dir", kCamera, fs::path());
  expect_refused("replay://good", "camera file", fs::path());

  // Only under replay_dir: no way out by .., an absolute path or a symbolic link.
  const fs::path outside = testing_support::temp_dir("replay") / "outside";
  fs::create_directories(outside);
  io::write_tiff(outside / "a.tif", frame_image(0), false);
  io::write_tiff(outside / "b.tif", frame_image(1), false);
  expect_refused("replay://../outside", "outside replay_dir");
  expect_refused("replay://../does-not-exist", "outside replay_dir");  // no probing what exists
  expect_refused("replay://" + outside.string(), "outside replay_dir");
  fs::remove(replay_root() / "link");
  fs::create_directory_symlink(outside, replay_root() / "link");
  expect_refused("replay://link", "outside replay_dir");
  expect_refused("replay://good/pair-0-A.tif", "not a folder");

  const fs::path empty = replay_root() / "empty";
  fs::create_directories(empty);
  expect_refused("replay://empty", "no manifest.json and no *.tif");

  const fs::path odd = tiff_folder("odd", 1);
  io::write_tiff(odd / "pair-1-A.tif", frame_image(2), false);
  expect_refused("replay://odd", "'pair-1-A.tif' has no partner");

  const fs::path narrow = tiff_folder("narrow", 1, 849);
  expect_refused("replay://narrow", (narrow / "pair-0-A.tif").string() + "' is 849 x 850 px");
  expect_refused("replay://narrow", "camera-small.yaml");

  // A FIFO is never opened (it would block the daemon).
  const fs::path fifo = tiff_folder("fifo", 1);
  ASSERT_EQ(::mkfifo((fifo / "pair-1-A.tif").c_str(), 0600), 0);
  io::write_tiff(fifo / "pair-1-B.tif", frame_image(3), false);
  expect_refused("replay://fifo", "pair-1-A.tif' is not a regular file");

  const fs::path corrupt = tiff_folder("corrupt", 1);
  fs::resize_file(corrupt / "pair-0-B.tif", 1000);
  EXPECT_NE(refusal("replay://corrupt").find("pair-0-B.tif"), std::string::npos) << refusal("replay://corrupt");
}

TEST(ReplayCamera, IsNotInTheRegistryUntilRegistered) {
  try {
    CameraRegistry::instance().open("replay://good");
    ADD_FAILURE() << "replay:// opened without being registered";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not registered"), std::string::npos) << e.what();
  }
  CameraRegistry registry;
  register_replay_camera(registry, ReplaySource{replay_root(), kCamera});
  tiff_folder("registered", 1);
  EXPECT_EQ(registry.open("replay://registered")->info().model, "replay camera");
}

}  // namespace
}  // namespace plenopiv::drivers
