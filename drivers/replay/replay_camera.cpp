// The replay camera, `replay://`: plays recorded frame pairs (a run folder or a folder of TIFF
// files) through the camera interface, triggered or free-running, at any rate.
#include "drivers/replay/replay_camera.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>
#include <vector>

#include "core/base/errors.hpp"
#include "core/base/memory.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "drivers/camera/camera_base.hpp"
#include "proto/run_folder.hpp"

namespace plenopiv::drivers {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct PairFiles {
  fs::path a, b;
};

struct DecodedPair {
  ImageU16 a, b;
};

struct ReplaySettings {
  double rate_hz = 0;  // 0: triggered
  bool loop = false;
  std::uint64_t buffer_bytes = kReplayDefaultBufferMb << 20;
};

bool inside(const fs::path& path, const fs::path& root) {
  auto [r, p] = std::mismatch(root.begin(), root.end(), path.begin(), path.end());
  return r == root.end();
}

// The folder the URI names, resolved (symbolic links too) and checked to lie inside replay_dir.
fs::path replay_folder(const DeviceUri& uri, const fs::path& replay_dir) {
  if (replay_dir.empty()) {
    uri.fail(
        "no replay_dir: the replay camera reads only under the folder the daemon's config names "
        "(plenopivd.yaml replay_dir, or --replay-dir)");
  }
  std::error_code ec;
  const fs::path root = fs::canonical(replay_dir, ec);
  if (ec) uri.fail("replay_dir '" + replay_dir.string() + "': " + ec.message());
  const fs::path named(uri.target());
  const fs::path candidate = (named.is_absolute() ? named : root / named).lexically_normal();
  // Refused before the file system is asked, so a URI cannot probe what exists outside.
  const auto refuse_outside = [&](const fs::path& p) {
    uri.fail("folder '" + p.string() + "' is outside replay_dir '" + root.string() +
             "': the replay camera reads only under it");
  };
  if (!inside(candidate, root)) refuse_outside(candidate);
  const fs::path folder = fs::canonical(candidate, ec);
  if (ec) uri.fail("folder '" + candidate.string() + "': " + ec.message());
  if (!inside(folder, root)) refuse_outside(folder);  // through a symbolic link
  if (!fs::is_directory(folder)) uri.fail("'" + folder.string() + "' is not a folder");
  return folder;
}

// Frames of a plain folder: every regular *.tif / *.tiff, sorted by name, two by two.
std::vector<PairFiles> tiff_pairs(const DeviceUri& uri, const fs::path& folder) {
  std::vector<fs::path> files;
  for (const fs::directory_entry& e : fs::directory_iterator(folder)) {
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext != ".tif" && ext != ".tiff") continue;
    // No FIFOs, devices or links out of the folder: only plain files are read.
    if (!e.is_regular_file() || e.is_symlink()) {
      uri.fail("'" + e.path().string() + "' is not a regular file");
    }
    files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) uri.fail("folder '" + folder.string() + "' holds no manifest.json and no *.tif frames");
  if (files.size() % 2 != 0) {
    uri.fail("folder '" + folder.string() + "' holds " + std::to_string(files.size()) +
             " TIFF files, an odd number: '" + files.back().filename().string() +
             "' has no partner (frames are taken two by two in name order: A, B)");
  }
  std::vector<PairFiles> pairs;
  for (std::size_t i = 0; i < files.size(); i += 2) pairs.push_back({files[i], files[i + 1]});
  return pairs;
}

std::vector<PairFiles> run_pairs(const DeviceUri& uri, const fs::path& folder) {
  std::vector<PairFiles> pairs;
  const run_folder::Reader reader(folder);
  for (const run_folder::PairEntry& p : reader.pairs()) {
    for (const fs::path& f : {p.frame_a, p.frame_b}) {
      if (!fs::is_regular_file(fs::symlink_status(f))) uri.fail("'" + f.string() + "' is not a regular file");
    }
    pairs.push_back({p.frame_a, p.frame_b});
  }
  if (pairs.empty()) uri.fail("run folder '" + folder.string() + "' has recorded no pairs");
  return pairs;
}

DecodedPair decode(const PairFiles& files) { return {io::read_tiff_u16(files.a), io::read_tiff_u16(files.b)}; }

// Plays the recording on its own thread. Triggers (edges, software triggers, or the free-running
// clock) queue up as pending exposures; the player delivers each from decoded frames: the
// preloaded recording (decoded at the first start(), on the caller's thread: plenopivd's run
// thread, so that opening the camera, which answers `run start`, reads headers only), or the
// read-ahead queue a second thread keeps filled.
class ReplayCamera : public CameraBase, public TriggerInput {
 public:
  // An exposure to play: its trigger index (counted from start) and when it was triggered.
  struct Pending {
    std::uint64_t trigger = 0;
    Clock::time_point at;
  };
  ReplayCamera(CameraInfo info, std::vector<PairFiles> files, ReplaySettings settings, int bit_depth,
               std::uint64_t pair_bytes)
      : CameraBase(std::move(info)),
        files_(std::move(files)),
        settings_(settings),
        bit_depth_(bit_depth),
        epoch_(Clock::now()),
        preload_(files_.size() * pair_bytes <= settings_.buffer_bytes) {
    if (!preload_) {
      ahead_capacity_ = std::size_t(settings_.buffer_bytes / pair_bytes);
      reader_ = std::thread([this] { read_ahead_loop(); });
    }
    player_ = std::thread([this] { play_loop(); });
  }

  ~ReplayCamera() override {
    {
      std::lock_guard lock(mutex_);
      quit_ = true;
    }
    wake_.notify_all();
    space_.notify_all();
    player_.join();
    if (reader_.joinable()) reader_.join();
  }

 private:
  void do_configure(const CameraSettings& settings) override {
    const Roi& roi = settings.roi;
    const CameraInfo i = info();
    if (roi.x != 0 || roi.y != 0 || (roi.width != 0 && roi.width != i.sensor_width_px) ||
        (roi.height != 0 && roi.height != i.sensor_height_px)) {
      throw InputError(i.uri + ": roi: the replay camera plays the recorded full frames only");
    }
  }
  void do_arm(const DoubleExposureSettings& settings) override {
    external_ = settings.trigger == TriggerSource::External;
  }
  void do_start() override {
    // The whole recording, decoded once (a failure to read a frame fails the start, naming it).
    // Written before running_ is set under the mutex; the player reads it only after it saw that.
    if (preload_ && preloaded_.empty()) {
      std::vector<DecodedPair> decoded;
      decoded.reserve(files_.size());
      for (const PairFiles& f : files_) decoded.push_back(decode(f));
      preloaded_ = std::move(decoded);
    }
    frame_buffers().prefill(info().sensor_width_px, info().sensor_height_px);
    {
      std::lock_guard lock(mutex_);
      running_ = true;
      next_tick_ = Clock::now();
      next_trigger_ = 0;  // trigger indices count from start, as the trigger counts its shots
    }
    wake_.notify_all();
  }
  // Exposures already triggered are delivered (waited for up to kStopDrain); what is left then is
  // dropped as not read out.
  void do_stop() override {
    std::unique_lock lock(mutex_);
    running_ = false;
    wake_.notify_all();
    if (!idle_.wait_for(lock, kStopDrain, [this] { return pending_.empty() && !playing_; })) {
      for (const Pending& p : pending_) report_dropped(p.trigger, PairDrop::Reason::NotReadOut);
      pending_.clear();
      idle_.wait(lock, [this] { return !playing_; });
    }
  }
  // A free-running camera ignores triggers, as one in free-run mode ignores its line.
  void do_software_trigger() override {
    if (settings_.rate_hz > 0) return;
    {
      std::lock_guard lock(mutex_);
      pending_.push_back({next_trigger_++, Clock::now()});
    }
    wake_.notify_all();
  }
  TriggerInput* trigger_input() override { return settings_.rate_hz > 0 ? nullptr : this; }
  void rising_edge() override {
    if (external_ && wanted_state() == CameraState::Running) do_software_trigger();
  }

  void play_loop() {
    const auto period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(settings_.rate_hz > 0 ? 1.0 / settings_.rate_hz : 1.0));
    for (;;) {
      Pending exposure;
      {
        std::unique_lock lock(mutex_);
        if (settings_.rate_hz > 0) {
          wake_.wait(lock, [this] { return quit_ || (running_ && !ended_); });
          if (quit_) return;
          if (wake_.wait_until(lock, next_tick_, [this] { return quit_ || !running_; })) {
            if (quit_) return;
            continue;
          }
          exposure = {next_trigger_++, next_tick_};
          next_tick_ += period;
        } else {
          wake_.wait(lock, [this] { return quit_ || !pending_.empty(); });
          if (quit_) return;
          exposure = pending_.front();
          pending_.pop_front();
        }
        playing_ = true;
      }
      play(exposure);
      {
        std::lock_guard lock(mutex_);
        playing_ = false;
      }
      idle_.notify_all();
    }
  }

  // The next recorded pair, or nullopt: not decoded yet (lost) or the end (ended_ set).
  std::optional<DecodedPair> next_recorded() {
    if (preload_) {
      if (cursor_ >= preloaded_.size()) {
        if (!settings_.loop) return std::nullopt;
        cursor_ = 0;
      }
      // Copied into buffers from the frame pool, as a camera fills its buffers: a loop plays the
      // same frames again, and at a steady rate the copies land in warm memory.
      const DecodedPair& recorded = preloaded_[cursor_++];
      return DecodedPair{frame_buffers().copy(recorded.a), frame_buffers().copy(recorded.b)};
    }
    std::lock_guard lock(mutex_);
    if (ahead_.empty()) return std::nullopt;
    DecodedPair p = std::move(ahead_.front());
    ahead_.pop_front();
    space_.notify_all();
    return p;
  }

  bool at_end() {
    if (settings_.loop) return false;
    if (preload_) return cursor_ >= preloaded_.size();
    std::lock_guard lock(mutex_);
    return ahead_.empty() && read_all_;
  }

  void play(const Pending& exposure) {
    if (at_end()) {
      std::lock_guard lock(mutex_);
      ended_ = true;
      if (settings_.rate_hz > 0) return;  // free-running: the acquisition just ends
      report_failed("end of the recording: all " + std::to_string(files_.size()) + " pairs played, trigger " +
                    std::to_string(exposure.trigger) + " has none (loop=1 plays the recording again)");
      return;
    }
    std::optional<DecodedPair> pair = next_recorded();
    if (!pair) return;  // not decoded in time: both frames lost (a gap in the frame ids)
    const std::uint64_t device_ns =
        std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(exposure.at - epoch_).count());
    Frame a = frame(std::move(pair->a), 2 * exposure.trigger + 1, device_ns);
    Frame b = frame(std::move(pair->b), 2 * exposure.trigger + 2, device_ns + 1000);
    a.host_timestamp_ns = host_now_ns();
    submit_frame(std::move(a), exposure.trigger);
    b.host_timestamp_ns = host_now_ns();
    submit_frame(std::move(b), exposure.trigger);
  }

  Frame frame(ImageU16 image, std::uint64_t id, std::uint64_t device_ns) const {
    Frame f;
    f.image = std::move(image);
    f.bit_depth = bit_depth_;
    f.frame_id = id;
    f.device_timestamp_ns = device_ns;
    f.complete = true;
    return f;
  }

  void read_ahead_loop() {
    std::size_t next = 0;
    for (;;) {
      {
        std::unique_lock lock(mutex_);
        space_.wait(lock, [this] { return quit_ || ahead_.size() < ahead_capacity_; });
        if (quit_) return;
      }
      if (next == files_.size()) {
        if (!settings_.loop) {
          std::lock_guard lock(mutex_);
          read_all_ = true;
          return;
        }
        next = 0;
      }
      try {
        // Decoded into buffers the frame pool has spare, as a camera fills its buffers.
        const CameraInfo camera = info();
        DecodedPair p;
        for (auto [image, file] : {std::pair{&p.a, &files_[next].a}, std::pair{&p.b, &files_[next].b}}) {
          if (auto spare = frame_buffers().reuse(camera.sensor_width_px, camera.sensor_height_px)) {
            *image = std::move(*spare);
          }
          io::read_tiff_u16(*file, *image);
        }
        ++next;
        std::lock_guard lock(mutex_);
        ahead_.push_back(std::move(p));
      } catch (const std::exception& e) {
        report_failed(std::string("reading the recording failed: ") + e.what());
        std::lock_guard lock(mutex_);
        read_all_ = true;
        return;
      }
    }
  }

  static constexpr std::chrono::milliseconds kStopDrain{2000};

  const std::vector<PairFiles> files_;
  const ReplaySettings settings_;
  const int bit_depth_;
  const Clock::time_point epoch_;       // the replay's device clock starts at open
  const bool preload_;                  // the whole recording fits the budget: decoded at the first start
  std::vector<DecodedPair> preloaded_;  // the whole recording, once decoded
  std::size_t cursor_ = 0;              // next preloaded pair (player thread only)
  std::size_t ahead_capacity_ = 0;

  std::atomic<bool> external_{false};
  std::mutex mutex_;
  std::condition_variable wake_;   // a trigger, start/stop, quit
  std::condition_variable idle_;   // the player finished an exposure
  std::condition_variable space_;  // the read-ahead queue has room, or quit
  std::deque<Pending> pending_;
  std::deque<DecodedPair> ahead_;
  bool read_all_ = false;  // the read-ahead reached the end (no loop) or failed
  bool ended_ = false;
  bool running_ = false;
  bool playing_ = false;
  bool quit_ = false;
  Clock::time_point next_tick_;
  std::uint64_t next_trigger_ = 0;
  std::thread reader_;
  std::thread player_;
};

}  // namespace

std::unique_ptr<Camera> open_replay_camera(const DeviceUri& uri, const ReplaySource& source) {
  uri.reject_unknown({"rate_hz", "loop", "buffer_mb"});
  ReplaySettings settings;
  settings.rate_hz = uri.number_or("rate_hz", 0.0);
  if (!(settings.rate_hz >= 0) || settings.rate_hz > 1000) uri.fail("rate_hz: must be in [0, 1000] Hz (0: triggered)");
  const long long loop = uri.integer_or("loop", 0);
  if (loop != 0 && loop != 1) uri.fail("loop: 0 or 1");
  settings.loop = loop == 1;
  const long long buffer_mb = uri.integer_or("buffer_mb", kReplayDefaultBufferMb);
  if (buffer_mb <= 0) uri.fail("buffer_mb: must be > 0");
  settings.buffer_bytes = std::uint64_t(buffer_mb) << 20;
  if (source.camera_file.empty()) {
    uri.fail(
        "the replay camera needs a camera file, whose sensor size the frames must have: "
        "plenopivd.yaml "
        "camera_file or --camera-file");
  }
  const optics::CameraModel camera = optics::load_camera_file(source.camera_file);
  const int width = camera.sensor().width_px, height = camera.sensor().height_px;

  const fs::path folder = replay_folder(uri, source.replay_dir);
  const std::vector<PairFiles> files =
      fs::exists(folder / "manifest.json") ? run_pairs(uri, folder) : tiff_pairs(uri, folder);
  int bits = 0;
  for (const PairFiles& p : files) {
    for (const fs::path& f : {p.a, p.b}) {
      const io::TiffInfo info = io::check_tiff(f);
      if (info.width != width || info.height != height) {
        uri.fail("frame '" + f.string() + "' is " + std::to_string(info.width) + " x " + std::to_string(info.height) +
                 " px, the camera file (" + source.camera_file.string() + ") has a " + std::to_string(width) + " x " +
                 std::to_string(height) + " px sensor");
      }
      bits = std::max(bits, info.bits);
    }
  }
  const std::uint64_t pair_bytes = 2 * std::uint64_t(width) * std::uint64_t(height) * sizeof(std::uint16_t);
  if (settings.buffer_bytes < 2 * pair_bytes) {
    uri.fail("buffer_mb: " + std::to_string(buffer_mb) + " MB holds fewer than two pairs of " +
             std::to_string(pair_bytes >> 20) + " MB");
  }
  require_memory(double(std::min<std::uint64_t>(settings.buffer_bytes, files.size() * pair_bytes)),
                 "the replay camera's frame buffer (buffer_mb)");

  CameraInfo info;
  info.uri = uri.text();
  info.vendor = "plenopiv";
  info.model = "replay camera";
  info.serial = folder.filename().string();
  info.sensor_width_px = width;
  info.sensor_height_px = height;
  info.double_exposure =
      "recorded frame pair per " + std::string(settings.rate_hz > 0 ? "tick of its own clock" : "trigger");
  return std::make_unique<ReplayCamera>(std::move(info), files, settings, bits, pair_bytes);
}

void register_replay_camera(CameraRegistry& registry, const ReplaySource& source) {
  registry.add("replay", [source](const DeviceUri& uri) { return open_replay_camera(uri, source); });
}

}  // namespace plenopiv::drivers
