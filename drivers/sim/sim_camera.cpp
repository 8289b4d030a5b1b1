// The simulated plenoptic camera, `sim://`: each trigger renders a particle pair with core/sim.
#include "drivers/sim/sim_camera.hpp"

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>

#include "core/base/errors.hpp"
#include "core/base/memory.hpp"
#include "core/optics/camera_file.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "drivers/camera/camera_base.hpp"

namespace plenopiv::drivers {
namespace {

struct SceneSettings {
  std::uint64_t seed = 1;
  double ppm = 0.05;
  double depth_mm = 5.0;
  std::size_t rays = 2000;
  // Each particle's light a log-normal factor of this spread (sim::RenderOptions::brightness_spread;
  // 0 to 3, default 0: every particle alike), drawn per pair so a particle keeps it in A and B.
  double brightness_spread = 0;
  bool noise = false;
  // With noise: the sensor's right half read out this many counts above the left (a second
  // readout tap's offset), [0, 1000]; default 0.
  std::uint64_t tap_offset = 0;
  std::uint64_t drop_every = 0;
  std::uint64_t incomplete_every = 0;
  std::uint64_t disconnect_after = 0;
  std::uint64_t fail_after = 0;
  double readout_s = 0.01;
  // The pulse separation the flow's displacements belong to. When a simulated trigger reports an
  // exposure's two laser pulses, the scene moves by the flow scaled to the time between them.
  double flow_dt_s = 1e-4;
  // The true lens array turned from the nominal lattice (as `plenopiv simulate --array-rotation-rad`):
  // frames a calibration must correct.
  double array_rotation_rad = 0;
};

std::unique_ptr<sim::Flow> flow_from_uri(const DeviceUri& uri, const optics::CameraModel& camera) {
  const std::string name = uri.string_or("flow", "uniform");
  if (name == "uniform") {
    return std::make_unique<sim::UniformFlow>(
        sim::Point3{uri.number_or("dx_mm", 0.25), uri.number_or("dy_mm", 0.0), uri.number_or("dz_mm", 0.0)});
  }
  if (name == "ring") {
    sim::RingVortexFlow::Parameters p;
    p.voxel_mm = uri.number_or("voxel_mm", camera.nominal_voxel_size_mm());
    return std::make_unique<sim::RingVortexFlow>(p);
  }
  if (name == "rotation") {
    const double angle = uri.number_or("angle_deg", 1.0) * std::acos(-1.0) / 180.0;
    return std::make_unique<sim::SolidBodyRotation>(sim::Point3{0, 0, 0}, sim::Point3{0, 1, 0}, angle);
  }
  if (name == "shear") {
    return std::make_unique<sim::LinearShear>(sim::Point3{uri.number_or("shear_per_mm", 0.02), 0, 0}, 1, 0.0);
  }
  uri.fail("flow: unknown flow '" + name + "' (uniform, ring, rotation, shear)");
}

// Renders on its own thread, so a trigger never waits for the ray tracer: the queue of pending
// triggers is what a real camera's exposure pipeline would be. Armed for External, the pairs are
// made by rising edges on its trigger input (a simulated trigger's camera line); for Software,
// by software_trigger().
class SimCamera : public CameraBase, public TriggerInput {
 public:
  SimCamera(const DeviceUri& uri, optics::CameraModel camera, SceneSettings scene, std::unique_ptr<sim::Flow> flow)
      : CameraBase(make_info(uri, camera)),
        camera_(std::move(camera)),
        array_(true_array(camera_, scene.array_rotation_rad)),
        scene_(scene),
        flow_(std::move(flow)),
        box_(sim::field_of_view_box(camera_, -scene.depth_mm, scene.depth_mm)),
        particle_count_(sim::particle_count_from_ppm(camera_, box_, scene.ppm)),
        readout_(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
            std::chrono::duration<double>(scene.readout_s))) {
    options_.rays_per_particle = scene_.rays;
    options_.brightness_spread = scene_.brightness_spread;
    // Checked about a hundred times per frame: a stop gives up a long ray trace within a moment.
    options_.progress = [this](double) {
      if (abort_render_) throw Cancelled("simulated camera stopped");
    };
    if (scene_.noise) {
      options_.sensor.shot_noise = true;
      options_.sensor.read_noise_electrons = 8.0;
      options_.sensor.dark_offset_dn = 20.0;
      options_.sensor.electrons_per_ray = 4.0;
      options_.sensor.bit_depth = 12;
      options_.sensor.right_half_offset_dn = double(scene_.tap_offset);
    }
    worker_ = std::thread([this] { render_loop(); });
  }

  ~SimCamera() override {
    {
      std::lock_guard lock(mutex_);
      quit_ = true;
    }
    wake_.notify_all();
    worker_.join();
  }

 private:
  static optics::MicrolensArray true_array(const optics::CameraModel& camera, double rotation_rad) {
    optics::Lattice lattice = optics::Lattice::nominal(camera);
    lattice.rotation_rad = rotation_rad;
    return optics::MicrolensArray::from_lattice(lattice);
  }

  static CameraInfo make_info(const DeviceUri& uri, const optics::CameraModel& camera) {
    CameraInfo info;
    info.uri = uri.text();
    info.vendor = "plenopiv";
    info.model = "simulated plenoptic camera";
    info.serial = "seed-" + uri.string_or("seed", "1");
    info.sensor_width_px = camera.sensor().width_px;
    info.sensor_height_px = camera.sensor().height_px;
    info.double_exposure = "simulated frame pair per trigger";
    return info;
  }

  void do_configure(const CameraSettings& settings) override {
    const Roi& roi = settings.roi;
    if (roi.x != 0 || roi.y != 0 || (roi.width != 0 && roi.width != camera_.sensor().width_px) ||
        (roi.height != 0 && roi.height != camera_.sensor().height_px)) {
      throw InputError(info().uri + ": roi: the simulated camera renders the full sensor only");
    }
  }
  TriggerInput* trigger_input() override { return this; }
  void rising_edge() override {
    if (external_ && wanted_state() == CameraState::Running) do_software_trigger();
  }
  // The pulses after a trigger belong to its exposure (the camera line rises before pulse 1).
  void laser_pulse(std::uint64_t time_ns) override {
    std::lock_guard lock(mutex_);
    if (!pending_.empty() && pending_.back().pulses < 2) pending_.back().pulse_ns[pending_.back().pulses++] = time_ns;
  }

  void do_arm(const DoubleExposureSettings& settings) override {
    external_ = settings.trigger == TriggerSource::External;
  }
  void do_start() override {}
  // Exposures already triggered are delivered, as a real camera's would be: waited for up to
  // kStopDrain. What is not rendered by then (a ray trace takes seconds on a large camera) is
  // dropped as not read out, and the render in progress is given up, so a stop is bounded.
  void do_stop() override {
    std::unique_lock lock(mutex_);
    if (idle_.wait_for(lock, kStopDrain, [this] { return pending_.empty() && !rendering_; })) return;
    for (const Pending& p : pending_) report_dropped(p.trigger, PairDrop::Reason::NotReadOut);
    pending_.clear();
    abort_render_ = true;
    idle_.wait(lock, [this] { return !rendering_; });
    abort_render_ = false;
  }

  // The pair is rendered once frame B would have been read out: rendering during the laser
  // pulses would take the cores from the trigger that times them (on 2 cores it made the sim
  // trigger write Q-switch 1 up to 0.9 ms late).
  void do_software_trigger() override {
    {
      std::lock_guard lock(mutex_);
      pending_.push_back({next_trigger_++, std::chrono::steady_clock::now() + readout_, {0, 0}, 0});
    }
    wake_.notify_all();
  }

  void render_loop() {
    for (;;) {
      Pending exposure;
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [this] { return quit_ || !pending_.empty(); });
        if (quit_) return;
        const auto due = pending_.front().due;
        if (wake_.wait_until(lock, due, [this] { return quit_.load(); })) return;
        exposure = pending_.front();
        pending_.pop_front();
        rendering_ = true;
      }
      // Two pulses seen: the scene moved for the time between them; otherwise (software trigger)
      // by the flow as given.
      const double scale = exposure.pulses == 2 && exposure.pulse_ns[1] > exposure.pulse_ns[0]
                               ? double(exposure.pulse_ns[1] - exposure.pulse_ns[0]) * 1e-9 / scene_.flow_dt_s
                               : 1.0;
      try {
        render_pair(exposure.trigger, scale);
      } catch (const Cancelled&) {
        report_dropped(exposure.trigger, PairDrop::Reason::NotReadOut);
      } catch (const std::exception& e) {
        // The render thread never dies silently: the camera fails, the run that uses it fails
        // with this reason, and the daemon goes on.
        report_failed("rendering trigger " + std::to_string(exposure.trigger) + " failed: " + e.what());
        std::lock_guard lock(mutex_);
        pending_.clear();
      }
      {
        std::lock_guard lock(mutex_);
        rendering_ = false;
      }
      idle_.notify_all();
    }
  }

  void render_pair(std::uint64_t trigger, double flow_scale) {
    if (scene_.disconnect_after && trigger >= scene_.disconnect_after) {
      report_lost("simulated disconnect after " + std::to_string(scene_.disconnect_after) + " triggers");
      return;
    }
    if (scene_.fail_after && trigger >= scene_.fail_after) {
      throw std::runtime_error("simulated render fault after " + std::to_string(scene_.fail_after) + " triggers");
    }
    // Pair k depends on (seed, k) only: the same run renders the same frames.
    const std::uint64_t pair_seed = scene_.seed * 0x9E3779B97F4A7C15ull + trigger;
    const std::vector<sim::Point3> a = sim::random_particles(box_, particle_count_, pair_seed);
    std::vector<sim::Point3> b = sim::displace(a, *flow_);
    if (flow_scale != 1.0) {
      // Displacement proportional to the pulse separation (to first order for non-uniform flows).
      for (std::size_t i = 0; i < b.size(); ++i)
        for (int k = 0; k < 3; ++k) b[i][k] = a[i][k] + flow_scale * (b[i][k] - a[i][k]);
    }
    // Both frames are rendered before either is delivered: a camera's frame B follows A by one
    // read-out, not by a ray trace (a large camera's render outlasts the pairer's wait for a B,
    // which would discard whole pairs).
    const std::uint64_t t0 = host_now_ns();
    // Each particle's brightness from the pair's seed, so both frames light it alike.
    options_.brightness_seed = pair_seed;
    Frame fa = make_frame(a, 2 * trigger, pair_seed, t0);
    Frame fb = make_frame(b, 2 * trigger + 1, pair_seed + 1, t0 + 1000);
    if (scene_.incomplete_every && (trigger + 1) % scene_.incomplete_every == 0) fb.complete = false;
    fa.host_timestamp_ns = host_now_ns();
    submit_frame(std::move(fa), trigger);
    if (scene_.drop_every && (trigger + 1) % scene_.drop_every == 0) return;
    fb.host_timestamp_ns = host_now_ns();
    submit_frame(std::move(fb), trigger);
  }

  Frame make_frame(const std::vector<sim::Point3>& particles, std::uint64_t id, std::uint64_t seed,
                   std::uint64_t device_ns) {
    sim::RenderResult r = sim::render(camera_, array_, particles, options_, seed);
    Frame f;
    f.image = std::move(r.image);
    f.bit_depth = options_.sensor.bit_depth;
    f.frame_id = id + 1;  // GigE Vision style: 0 means "unknown"
    f.device_timestamp_ns = device_ns;
    f.host_timestamp_ns = host_now_ns();  // set again when the frame is delivered
    f.complete = true;
    return f;
  }

  optics::CameraModel camera_;
  optics::MicrolensArray array_;
  SceneSettings scene_;
  std::unique_ptr<sim::Flow> flow_;
  sim::Box box_;
  std::size_t particle_count_;
  std::chrono::steady_clock::duration readout_;
  sim::RenderOptions options_;

  static constexpr std::chrono::milliseconds kStopDrain{2000};
  std::atomic<bool> external_{false};
  std::atomic<bool> abort_render_{false};
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable idle_;
  struct Pending {
    std::uint64_t trigger = 0;
    std::chrono::steady_clock::time_point due;
    std::uint64_t pulse_ns[2] = {0, 0};  // laser pulses reported during this exposure
    int pulses = 0;
  };
  std::deque<Pending> pending_;
  bool rendering_ = false;
  std::uint64_t next_trigger_ = 0;
  std::atomic<bool> quit_{false};
  std::thread worker_;
};

}  // namespace

std::unique_ptr<Camera> open_sim_camera(const DeviceUri& uri, const std::filesystem::path& camera_file) {
  if (uri.has("camera")) {
    uri.fail(
        "camera: a URI cannot name a file; the simulated camera renders the daemon's camera_file "
        "(plenopivd.yaml or --camera-file)");
  }
  uri.reject_unknown({"seed",
                      "ppm",
                      "depth_mm",
                      "flow",
                      "dx_mm",
                      "dy_mm",
                      "dz_mm",
                      "voxel_mm",
                      "angle_deg",
                      "shear_per_mm",
                      "rays",
                      "brightness_spread",
                      "noise",
                      "tap_offset",
                      "drop_every",
                      "incomplete_every",
                      "disconnect_after",
                      "fail_after",
                      "readout_ms",
                      "flow_dt_us",
                      "array_rotation_rad"});
  if (!uri.target().empty()) uri.fail("the simulated camera takes no device name, only ?parameters");
  if (camera_file.empty()) {
    uri.fail("the simulated camera needs a camera file: plenopivd.yaml camera_file or --camera-file");
  }
  optics::CameraModel camera = optics::load_camera_file(camera_file);
  // A pair in flight holds two frames, each a 16-bit image, its float ray counts and the tracer's
  // counters: refused with the estimate before the render thread tries to allocate them.
  const double pixels = double(camera.sensor().width_px) * double(camera.sensor().height_px);
  require_memory(2.0 * pixels * (sizeof(std::uint16_t) + sizeof(float) + sizeof(std::uint32_t)),
                 "the simulated camera's frames (" + std::to_string(camera.sensor().width_px) + " x " +
                     std::to_string(camera.sensor().height_px) + " px, " + camera_file.string() + ")");

  SceneSettings scene;
  auto count = [&](const char* key, long long fallback) -> std::uint64_t {
    const long long v = uri.integer_or(key, fallback);
    if (v < 0) uri.fail(std::string(key) + ": must be >= 0, got " + std::to_string(v));
    return std::uint64_t(v);
  };
  scene.seed = count("seed", 1);
  scene.ppm = uri.number_or("ppm", scene.ppm);
  if (!(scene.ppm > 0) || scene.ppm > 10) uri.fail("ppm: must be in (0, 10] particles per microlens");
  scene.depth_mm = uri.number_or("depth_mm", scene.depth_mm);
  if (!(scene.depth_mm > 0) || scene.depth_mm > 1000) uri.fail("depth_mm: must be in (0, 1000] mm");
  scene.rays = count("rays", 2000);
  if (scene.rays == 0) uri.fail("rays: must be > 0");
  scene.brightness_spread = uri.number_or("brightness_spread", 0.0);
  {
    sim::RenderOptions options;
    options.brightness_spread = scene.brightness_spread;
    try {
      sim::check_render_options(options);
    } catch (const InputError& e) {
      uri.fail(e.what());
    }
  }
  const std::uint64_t noise = count("noise", 0);
  if (noise > 1) uri.fail("noise: 0 or 1");
  scene.noise = noise == 1;
  scene.tap_offset = count("tap_offset", 0);
  if (scene.tap_offset > 1000) uri.fail("tap_offset: must be in [0, 1000] counts");
  if (scene.tap_offset > 0 && !scene.noise) uri.fail("tap_offset: needs noise=1 (a sensor's counts)");
  scene.drop_every = count("drop_every", 0);
  scene.incomplete_every = count("incomplete_every", 0);
  scene.disconnect_after = count("disconnect_after", 0);
  scene.fail_after = count("fail_after", 0);
  const double readout_ms = uri.number_or("readout_ms", scene.readout_s * 1e3);
  if (!(readout_ms >= 0) || readout_ms > 10000) uri.fail("readout_ms: must be in [0, 10000] ms");
  scene.readout_s = readout_ms * 1e-3;
  const double flow_dt_us = uri.number_or("flow_dt_us", scene.flow_dt_s * 1e6);
  if (!(flow_dt_us > 0) || flow_dt_us > 1e7) uri.fail("flow_dt_us: must be in (0, 1e7] us");
  scene.flow_dt_s = flow_dt_us * 1e-6;
  scene.array_rotation_rad = uri.number_or("array_rotation_rad", 0.0);
  if (!(std::abs(scene.array_rotation_rad) <= 0.1)) uri.fail("array_rotation_rad: must be in [-0.1, 0.1] rad");
  std::unique_ptr<sim::Flow> flow = flow_from_uri(uri, camera);
  return std::make_unique<SimCamera>(uri, std::move(camera), scene, std::move(flow));
}

void register_sim_camera(CameraRegistry& registry, const std::filesystem::path& camera_file) {
  registry.add("sim", [camera_file](const DeviceUri& uri) { return open_sim_camera(uri, camera_file); });
}

}  // namespace plenopiv::drivers
