// plenopivd as an object: its sockets, the run state, the current run, and one handler per request.
#include "daemon/daemon.hpp"

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <cstdio>
#include <filesystem>
#include <set>

#include "core/base/errors.hpp"
#include "core/base/isa.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "daemon/processing.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/replay/replay_camera.hpp"
#include "drivers/sim/sim_camera.hpp"

namespace plenopiv::daemon {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

// A run id whose folder does not exist yet (two runs in one second get -2, -3, ...).
std::string unused_run_id(const std::filesystem::path& data_dir, const std::string& prefix) {
  std::string id = run_folder::new_run_id();
  const std::string base = id;
  for (int n = 2; std::filesystem::exists(data_dir / (prefix + id)); ++n) {
    id = base + "-" + std::to_string(n);
  }
  return id;
}

// The processing a run gets, and one line for status saying what it is.
std::pair<ProcessFactory, std::string> choose_processing(const DaemonConfig& config,
                                                         const DaemonExtensions& extensions) {
  ProcessFactory factory = extensions.processing;
  std::string summary = extensions.processing_summary;
  if (config.camera_file.empty()) {
    if (!factory) summary = "none: no camera_file configured (raw frames are recorded)";
    return {factory, summary};
  }
  const optics::CameraModel camera = optics::load_camera_file(config.camera_file);
  spdlog::info("camera {}:\n{}", config.camera_file.string(), camera.summary());
  if (!factory) {
    factory = plenoptic_processing(camera, config.data_dir / kResponseCacheFolder);
    summary = "MART + multi-pass 3D correlation, " +
              (config.calibration_file.empty() ? "nominal lattice of " + config.camera_file.filename().string()
                                               : "calibration " + config.calibration_file.string());
  }
  // Checked now and again at each run start (it may be replaced meanwhile). A bad file does not
  // stop the daemon: it still serves status and takes calibration images for a new one, and
  // refuses runs, naming the file, until the file is fixed.
  if (config.calibration_file.empty()) {
    spdlog::info(
        "calibration: none configured (calibration_file): runs use the nominal lattice of {} and the "
        "geometric white image",
        config.camera_file.string());
  } else {
    try {
      spdlog::info("calibration: {}", load_run_calibration(config.calibration_file, camera).summary());
    } catch (const InputError& e) {
      spdlog::error("{}; runs are refused until it is fixed", e.what());
      summary += " (unusable at start: " + std::string(e.what()) + ")";
    }
  }
  return {factory, summary};
}

}  // namespace

Daemon::Daemon(DaemonConfig config, const DaemonExtensions& extensions)
    : config_(std::move(config)), started_(Clock::now()) {
  if (config_.simulation) {
    // sim:// renders with the same camera file the processing stage reconstructs with.
    drivers::register_sim_camera(drivers::CameraRegistry::instance(), config_.camera_file);
  } else {
    drivers::CameraRegistry::instance().add_unavailable(
        "sim", "the simulated camera is not enabled on this daemon (plenopivd.yaml simulation: true, or --simulation)");
  }
  if (config_.simulation && !config_.replay_dir.empty()) {
    // replay:// reads only under the folder the operator named at start, never one a request names.
    drivers::register_replay_camera(drivers::CameraRegistry::instance(),
                                    drivers::ReplaySource{config_.replay_dir, config_.camera_file});
  } else {
    drivers::CameraRegistry::instance().add_unavailable(
        "replay", config_.simulation
                      ? "the replay camera is not enabled on this daemon: it needs replay_dir "
                        "(plenopivd.yaml, or --replay-dir), the only folder it may read"
                      : "the replay camera is not enabled on this daemon (plenopivd.yaml simulation: true "
                        "and replay_dir, or --simulation --replay-dir)");
  }
  std::tie(processing_factory_, processing_) = choose_processing(config_, extensions);

  std::optional<wire::CurveCertificate> server_certificate;
  if (config_.curve) {
    server_certificate = wire::read_certificate(config_.curve->server_certificate);
    if (server_certificate->secret_key.empty()) {
      throw InputError("curve: server_certificate: " + config_.curve->server_certificate.string() +
                       " holds no secret-key: give the server's .key_secret file");
    }
    const std::vector<std::string> keys = wire::read_public_keys(config_.curve->authorized_clients);
    spdlog::info("CURVE: {} authorized client key(s) from {}", keys.size(), config_.curve->authorized_clients.string());
    zap_ = std::make_unique<ZapAuthenticator>(context_, std::set<std::string>(keys.begin(), keys.end()));
  }
  publisher_ = std::make_unique<Publisher>(context_, config_.publish_endpoint, config_.publish_high_water_mark,
                                           config_.curve && config_.curve->publish ? server_certificate : std::nullopt);
  ControlSecurity security;
  security.curve = server_certificate;
  security.ipc_group = config_.control_socket_group;
  server_ = std::make_unique<ControlServer>(
      context_, config_.control_endpoint, [this](const msg::Request& r) { return handle(r); }, security);

  std::vector<std::string> problems;
  for (const auto& dir : run_folder::mark_interrupted_runs(config_.data_dir, &problems)) {
    spdlog::warn("run folder {} was left recording by a daemon that did not close it: marked interrupted",
                 dir.string());
  }
  for (const std::string& p : problems) spdlog::warn("run folder {}: not checked", p);

  environment_.data_dir = config_.data_dir;
  environment_.default_camera_uri = config_.camera_uri;
  environment_.default_trigger_uri = config_.trigger_uri;
  environment_.camera_file = config_.camera_file;
  environment_.calibration_file = config_.calibration_file;
  environment_.timing = config_.timing;
  environment_.processing_nice = config_.processing_nice;
  environment_.state = &state_;
  environment_.publisher = publisher_.get();
  environment_.processing = processing_factory_;
  environment_.processing_reads_camera_file = !extensions.processing && !config_.camera_file.empty();
  environment_.heartbeat = [this] { last_progress_ns_ = now_ns(); };
  last_progress_ns_ = now_ns();
}

Daemon::~Daemon() { shutdown(); }

msg::Status Daemon::status() const {
  msg::Status s;
  s.set_state(to_string(state_.state()));
  s.set_message(state_.error());
  s.set_version(PLENOPIV_VERSION);
  s.set_kernels(isa_name(isa()));
  s.set_uptime_s(std::chrono::duration<double>(Clock::now() - started_).count());
  s.set_camera_uri(config_.camera_uri);
  s.set_trigger_uri(config_.trigger_uri);
  s.set_processing(processing_);
  if (run_) run_->fill_status(s);
  return s;
}

HandlerResult Daemon::handle(const msg::Request& request) {
  switch (request.kind_case()) {
    case msg::Request::kStatus: {
      msg::Reply reply;
      *reply.mutable_status() = status();
      return reply;
    }
    case msg::Request::kListDevices:
      return list_devices();
    case msg::Request::kStartRun:
      return start_run(request.start_run());
    case msg::Request::kStopRun:
      return stop_run();
    case msg::Request::kCalibrate:
      return calibrate(request.calibrate());
    default:
      return error_reply(request.id(), msg::Error::UNAVAILABLE, "unknown request");
  }
}

msg::Reply Daemon::start_run(const msg::StartRun& request) {
  RunConfig run_config = parse_run_config(request.config_yaml(), "run config");
  if (request.pair_count() > 0) run_config.pair_count = request.pair_count();
  const std::string id = unused_run_id(config_.data_dir, std::string(run_folder::kRunFolderPrefix));
  state_.start(id);
  if (run_) run_->join();  // the previous run's thread is past its last state change
  run_.reset();
  try {
    last_progress_ns_ = now_ns();
    run_ = std::make_unique<Run>(std::move(run_config), id, environment_);
  } catch (...) {
    state_.cancel_start();
    throw;
  }
  msg::Reply reply;
  reply.mutable_run_started()->set_run_id(id);
  reply.mutable_run_started()->set_run_dir(run_->dir().string());
  return reply;
}

msg::Reply Daemon::stop_run() {
  state_.stop();
  msg::Reply reply;
  reply.mutable_run_stopping();
  if (run_) {
    run_->request_stop();
    reply.mutable_run_stopping()->set_run_id(run_->run_id());
    reply.mutable_run_stopping()->set_run_dir(run_->dir().string());
  }
  return reply;
}

DeferredReply Daemon::list_devices() {
  if (!discovery_.valid() || discovery_.wait_for(0s) == std::future_status::ready) {
    discovery_ = std::async(std::launch::async, [] { return drivers::discover_devices(); }).share();
  }
  const bool simulation = config_.simulation;
  const std::filesystem::path replay_dir = simulation ? config_.replay_dir : std::filesystem::path();
  return std::async(std::launch::async, [found = discovery_, simulation, replay_dir] {
    msg::Reply reply;
    reply.mutable_devices();  // an empty list is still an answer
    // The simulated backends first, marked as such: sim:// always (said how to enable it when it
    // is not), replay:// when this daemon registered it, and the sim:// trigger, always there.
    const auto add_simulated = [&](const std::string& uri, const std::string& kind, const std::string& model,
                                   const std::string& detail) {
      msg::Device* d = reply.mutable_devices()->add_devices();
      d->set_uri(uri);
      d->set_kind(kind);
      d->set_model(model);
      d->set_detail(detail);
      d->set_simulated(true);
    };
    add_simulated("sim://", "camera", "simulated plenoptic camera",
                  simulation ? "renders the daemon's camera_file; enabled by simulation: true"
                             : "not enabled on this daemon: plenopivd.yaml simulation: true, or --simulation");
    if (!replay_dir.empty()) {
      add_simulated("replay://", "camera", "replay camera",
                    "plays recorded frame pairs from folders under " + replay_dir.string());
    }
    add_simulated("sim://", "trigger", "simulated trigger",
                  "no hardware: records every edge with its time; the simulated camera listens to it");
    for (const auto& d : found.get().devices) {
      msg::Device* out = reply.mutable_devices()->add_devices();
      out->set_uri(d.uri);
      out->set_kind(d.kind);
      out->set_model(d.model);
      out->set_detail(d.detail);
    }
    return reply;
  });
}

// Takes `frame_count` pairs with software triggers and writes frame A of each as a calibration image.
msg::Reply Daemon::calibrate(const msg::Calibrate& request) {
  state_.check_calibration_allowed();
  const std::string uri = request.camera_uri().empty() ? config_.camera_uri : request.camera_uri();
  if (uri.empty()) throw InputError("calibrate: camera_uri: none given and plenopivd.yaml has no camera_uri");
  const unsigned count = std::max(1u, request.frame_count());
  if (count > 1000) throw InputError("calibrate: frame_count: at most 1000 images, got " + std::to_string(count));
  std::unique_ptr<drivers::Camera> camera = drivers::open_camera(uri);
  camera->configure(drivers::CameraSettings{});
  camera->arm(drivers::DoubleExposureSettings{drivers::TriggerSource::Software, 0.0});
  const std::string id = unused_run_id(config_.data_dir, "calibration-");
  const std::filesystem::path dir = config_.data_dir / ("calibration-" + id);
  std::filesystem::create_directories(dir);
  camera->start();
  for (unsigned i = 0; i < count; ++i) {
    camera->software_trigger();
    const auto pair = camera->next_pair(5s);
    if (!pair) {
      camera->stop();
      throw std::runtime_error("calibrate: camera " + uri + " delivered no image within 5 s");
    }
    char name[32];
    std::snprintf(name, sizeof name, "image-%04u.tif", i);
    io::write_tiff(dir / name, pair->a.image);
  }
  camera->stop();
  spdlog::info("calibration: {} images from {} in {}", count, uri, dir.string());
  msg::Reply reply;
  reply.mutable_calibration()->set_dir(dir.string());
  reply.mutable_calibration()->set_frame_count(count);
  return reply;
}

void Daemon::notify_systemd(const msg::Status& s, std::string& last_state, bool watchdog, std::uint64_t watchdog_us) {
  if (s.state() != last_state) {
    last_state = s.state();
    const std::string line = "STATUS=" + s.state() + (s.run_id().empty() ? "" : " run " + s.run_id()) +
                             (s.message().empty() ? "" : ": " + s.message());
    sd_notify(0, line.c_str());
  }
  // The watchdog is fed while idle or arming (the control loop is alive; a run's setup is its own
  // thread's) and, during a run, only while pairs are being recorded or published: a stalled
  // pipeline lets systemd restart us.
  if (watchdog) {
    const RunState state = state_.state();
    const bool idle = state == RunState::Idle || state == RunState::Error || state == RunState::Armed;
    if (idle || now_ns() - last_progress_ns_ < std::int64_t(watchdog_us) * 1000 / 2) sd_notify(0, "WATCHDOG=1");
  }
}

void Daemon::serve(const std::atomic<bool>& stop) {
  std::uint64_t watchdog_us = 0;
  const bool watchdog = sd_watchdog_enabled(0, &watchdog_us) > 0;
  spdlog::info("plenopivd {} ready: control {}{}, publishing {}{}, data {}{}{}", PLENOPIV_VERSION, server_->endpoint(),
               config_.curve ? " (CURVE)" : "", publisher_->endpoint(),
               config_.curve && config_.curve->publish ? " (CURVE)" : "", config_.data_dir.string(),
               config_.simulation ? ", simulation enabled" : "",
               config_.replay_dir.empty() ? "" : ", replay:// reads under " + config_.replay_dir.string());
  sd_notify(0, "READY=1\nSTATUS=Idle");
  auto last_status = Clock::now();
  std::string last_state;
  while (!stop) {
    server_->serve_one(100);
    const msg::Status s = status();
    notify_systemd(s, last_state, watchdog, watchdog_us);
    if (Clock::now() - last_status >= 1s) {
      last_status = Clock::now();
      publisher_->publish_status(s);
    }
  }
}

void Daemon::shutdown() {
  if (!run_) return;
  if (state_.state() == RunState::Armed || state_.state() == RunState::Acquiring) state_.stop();
  run_->request_stop();
  run_->join();
  spdlog::info("run {} closed in {}", run_->run_id(), run_->dir().string());
  run_.reset();
}

}  // namespace plenopiv::daemon
