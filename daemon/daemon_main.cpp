// plenopivd's main loop: control requests, the run, status publishing, systemd notification.
#include "daemon/daemon_main.hpp"

#include "drivers/sim/sim_camera.hpp"

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <iostream>

#include "core/base/errors.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "daemon/control_server.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/processing.hpp"
#include "daemon/logging/logging.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/discovery/device_discovery.hpp"
#include "drivers/sim/sim_camera.hpp"

namespace plenopiv::daemon {
namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
      .count();
}

// A run id whose folder does not exist yet (two runs in one second get -2, -3, ...).
std::string unused_run_id(const std::filesystem::path& data_dir, const std::string& prefix) {
  std::string id = new_run_id();
  const std::string base = id;
  for (int n = 2; std::filesystem::exists(data_dir / (prefix + id)); ++n) {
    id = base + "-" + std::to_string(n);
  }
  return id;
}

// Takes `count` pairs with software triggers and writes frame A of each as a calibration image.
msg::CalibrationTaken calibrate(const DaemonConfig& config, const msg::Calibrate& request) {
  const std::string uri = request.camera_uri().empty() ? config.camera_uri : request.camera_uri();
  const unsigned count = std::max(1u, request.frame_count());
  if (count > 1000) throw InputError("calibrate: frame_count: at most 1000 images, got " +
                                     std::to_string(count));
  std::unique_ptr<drivers::Camera> camera = drivers::open_camera(uri);
  camera->configure(drivers::CameraSettings{});
  camera->arm(drivers::DoubleExposureSettings{drivers::TriggerSource::Software, 0.0});
  const std::string id = unused_run_id(config.data_dir, "calibration-");
  const std::filesystem::path dir = config.data_dir / ("calibration-" + id);
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
  msg::CalibrationTaken taken;
  taken.set_dir(dir.string());
  taken.set_frame_count(count);
  return taken;
}

}  // namespace

int daemon_main(int argc, char** argv, const DaemonExtensions& extensions) {
  CLI::App app{"plenopivd: single-camera plenoptic 3D/3C PIV daemon"};
  app.set_version_flag("--version", std::string(PLENOPIV_VERSION));
  std::filesystem::path config_path;
  std::string control, publish, data_dir, log_level, camera_uri, camera_file, calibration_file;
  app.add_option("-c,--config", config_path, "daemon config (plenopivd.yaml)")->check(CLI::ExistingFile);
  app.add_option("--control", control, "control endpoint (overrides the config)");
  app.add_option("--publish", publish, "publishing endpoint (overrides the config)");
  app.add_option("--data-dir", data_dir, "where run folders are written (overrides the config)");
  app.add_option("--camera", camera_uri, "default camera URI (overrides the config)");
  app.add_option("--camera-file", camera_file,
                 "camera description (YAML) the processing and sim:// use (overrides the config)")
      ->check(CLI::ExistingFile);
  app.add_option("--calibration-file", calibration_file,
                 "the rig's calibration file (HDF5, `plenopiv calibrate`) the processing uses (overrides the "
                 "config)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error");
  CLI11_PARSE(app, argc, argv);

  try {
    DaemonConfig config;
    if (!config_path.empty()) config = load_daemon_config(config_path);
    if (!control.empty()) config.control_endpoint = control;
    if (!publish.empty()) config.publish_endpoint = publish;
    if (!data_dir.empty()) config.data_dir = data_dir;
    if (!camera_uri.empty()) config.camera_uri = camera_uri;
    if (!camera_file.empty()) config.camera_file = camera_file;
    if (!calibration_file.empty()) config.calibration_file = calibration_file;
    if (!log_level.empty()) config.log_level = log_level;
    validate(config, config_path.empty() ? "command line" : config_path.string());
    setup_logging("plenopivd", config.log_level);
    // sim:// renders with the same camera file the processing stage reconstructs with.
    drivers::register_sim_camera(drivers::CameraRegistry::instance(), config.camera_file);

    ProcessFactory processing_factory = extensions.processing;
    std::string processing = extensions.processing_summary;
    if (!config.camera_file.empty()) {
      const optics::CameraModel camera = optics::load_camera_file(config.camera_file);
      spdlog::info("camera {}:\n{}", config.camera_file.string(), camera.summary());
      if (!processing_factory) {
        processing_factory = plenoptic_processing(camera);
        processing = "MART + multi-pass 3D correlation, " +
                     (config.calibration_file.empty()
                          ? "nominal lattice of " + config.camera_file.filename().string()
                          : "calibration " + config.calibration_file.string());
      }
      // Checked now and again at each run start (it may be replaced meanwhile). A bad file does
      // not stop the daemon: it still serves status and takes calibration images for a new one,
      // and refuses runs, naming the file, until the file is fixed.
      if (config.calibration_file.empty()) {
        spdlog::info("calibration: none configured (calibration_file): runs use the nominal lattice of {} and "
                     "the geometric white image",
                     config.camera_file.string());
      } else {
        try {
          spdlog::info("calibration: {}", load_run_calibration(config.calibration_file, camera).summary());
        } catch (const InputError& e) {
          spdlog::error("{}; runs are refused until it is fixed", e.what());
          processing += " (unusable at start: " + std::string(e.what()) + ")";
        }
      }
    }
    if (!processing_factory) processing = "none: no camera_file configured (raw frames are recorded)";

    std::signal(SIGTERM, on_signal);
    std::signal(SIGINT, on_signal);

    zmq::context_t context;
    Publisher publisher(context, config.publish_endpoint, config.publish_high_water_mark);
    RunStateMachine state;
    std::unique_ptr<Run> run;
    std::atomic<std::int64_t> last_progress{now_ns()};

    const auto started = Clock::now();
    auto status = [&] {
      msg::Status s;
      s.set_state(to_string(state.state()));
      s.set_message(state.error());
      s.set_version(PLENOPIV_VERSION);
      s.set_uptime_s(std::chrono::duration<double>(Clock::now() - started).count());
      s.set_camera_uri(config.camera_uri);
      s.set_trigger_uri(config.trigger_uri);
      s.set_processing(processing);
      if (run) run->fill_status(s);
      return s;
    };

    RunEnvironment environment;
    environment.data_dir = config.data_dir;
    environment.default_camera_uri = config.camera_uri;
    environment.default_trigger_uri = config.trigger_uri;
    environment.camera_file = config.camera_file;
    environment.calibration_file = config.calibration_file;
    environment.timing = config.timing;
    environment.state = &state;
    environment.publisher = &publisher;
    environment.processing = processing_factory;
    environment.heartbeat = [&] { last_progress = now_ns(); };

    ControlServer server(context, config.control_endpoint, [&](const msg::Request& req) {
      msg::Reply reply;
      switch (req.kind_case()) {
        case msg::Request::kStatus:
          *reply.mutable_status() = status();
          return reply;
        case msg::Request::kListDevices: {
          const drivers::DiscoveryReport found = drivers::discover_devices();
          reply.mutable_devices();  // an empty list is still an answer
          for (const auto& d : found.devices) {
            msg::Device* out = reply.mutable_devices()->add_devices();
            out->set_uri(d.uri);
            out->set_kind(d.kind);
            out->set_model(d.model);
            out->set_detail(d.detail);
          }
          return reply;
        }
        case msg::Request::kStartRun: {
          RunConfig run_config = parse_run_config(req.start_run().config_yaml(), "run config");
          if (req.start_run().pair_count() > 0) run_config.pair_count = req.start_run().pair_count();
          const std::string id = unused_run_id(config.data_dir, "run-");
          state.start(id);
          if (run) run->join();  // the previous run's thread is past its last state change
          run.reset();
          try {
            last_progress = now_ns();
            run = std::make_unique<Run>(std::move(run_config), id, environment);
          } catch (...) {
            state.cancel_start();
            throw;
          }
          reply.mutable_run_started()->set_run_id(id);
          reply.mutable_run_started()->set_run_dir(run->dir().string());
          return reply;
        }
        case msg::Request::kStopRun:
          state.stop();
          if (run) {
            run->request_stop();
            reply.mutable_run_stopping()->set_run_id(run->run_id());
            reply.mutable_run_stopping()->set_run_dir(run->dir().string());
          } else {
            reply.mutable_run_stopping();
          }
          return reply;
        case msg::Request::kCalibrate:
          state.check_calibration_allowed();
          *reply.mutable_calibration() = calibrate(config, req.calibrate());
          return reply;
        default:
          return error_reply(req.id(), msg::Error::UNAVAILABLE, "unknown request");
      }
    });

    std::uint64_t watchdog_us = 0;
    const bool watchdog = sd_watchdog_enabled(0, &watchdog_us) > 0;
    spdlog::info("plenopivd {} ready: control {}, publishing {}, data {}", PLENOPIV_VERSION,
                 server.endpoint(), publisher.endpoint(), config.data_dir.string());
    sd_notify(0, "READY=1\nSTATUS=Idle");

    auto last_status = Clock::now();
    std::string last_state;
    while (!g_stop) {
      server.serve_one(100);
      const msg::Status s = status();
      if (s.state() != last_state) {
        last_state = s.state();
        const std::string line = "STATUS=" + s.state() +
                                 (s.run_id().empty() ? "" : " run " + s.run_id()) +
                                 (s.message().empty() ? "" : ": " + s.message());
        sd_notify(0, line.c_str());
      }
      // The watchdog is fed while idle (the control loop is alive) and, during a run, only while
      // pairs are being recorded or published: a stalled pipeline lets systemd restart us.
      if (watchdog) {
        const bool idle = state.state() == RunState::Idle || state.state() == RunState::Error;
        if (idle || now_ns() - last_progress < std::int64_t(watchdog_us) * 1000 / 2) {
          sd_notify(0, "WATCHDOG=1");
        }
      }
      if (Clock::now() - last_status >= 1s) {
        last_status = Clock::now();
        publisher.publish_status(s);
      }
    }
    sd_notify(0, "STOPPING=1\nSTATUS=Stopping: draining the run");
    spdlog::info("plenopivd stopping");
    if (run) {
      if (state.state() == RunState::Armed || state.state() == RunState::Acquiring) state.stop();
      run->request_stop();
      run->join();
      spdlog::info("run {} closed in {}", run->run_id(), run->dir().string());
    }
    return 0;
  } catch (const InputError& e) {
    std::cerr << "plenopivd: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "plenopivd: fatal: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace plenopiv::daemon
