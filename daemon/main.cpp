// plenopivd: the plenopiv daemon — serves control requests and publishes status over ZeroMQ.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <iostream>

#include "core/base/errors.hpp"
#include "core/optics/camera_file.hpp"
#include "daemon/control_server.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/logging/logging.hpp"
#include "drivers/discovery/device_discovery.hpp"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

using Clock = std::chrono::steady_clock;

}  // namespace

int main(int argc, char** argv) {
  using namespace plenopiv;
  CLI::App app{"plenopivd: single-camera plenoptic 3D/3C PIV daemon"};
  app.set_version_flag("--version", std::string(PLENOPIV_VERSION));
  std::filesystem::path config_path;
  std::string control, publish, data_dir, log_level;
  app.add_option("-c,--config", config_path, "daemon config (plenopivd.yaml)")->check(CLI::ExistingFile);
  app.add_option("--control", control, "control endpoint (overrides the config)");
  app.add_option("--publish", publish, "publishing endpoint (overrides the config)");
  app.add_option("--data-dir", data_dir, "where run folders are written (overrides the config)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error");
  CLI11_PARSE(app, argc, argv);

  try {
    daemon::DaemonConfig config;
    if (!config_path.empty()) config = daemon::load_daemon_config(config_path);
    if (!control.empty()) config.control_endpoint = control;
    if (!publish.empty()) config.publish_endpoint = publish;
    if (!data_dir.empty()) config.data_dir = data_dir;
    if (!log_level.empty()) config.log_level = log_level;
    daemon::validate(config, config_path.empty() ? "command line" : config_path.string());
    setup_logging("plenopivd", config.log_level);

    std::optional<optics::CameraModel> camera;
    if (!config.camera_file.empty()) {
      camera = optics::load_camera_file(config.camera_file);
      spdlog::info("camera {}:\n{}", config.camera_file.string(), camera->summary());
    }

    std::signal(SIGTERM, on_signal);
    std::signal(SIGINT, on_signal);

    zmq::context_t context;
    zmq::socket_t publisher(context, zmq::socket_type::pub);
    publisher.set(zmq::sockopt::sndhwm, config.publish_high_water_mark);
    publisher.set(zmq::sockopt::linger, 0);
    try {
      publisher.bind(config.publish_endpoint);
    } catch (const zmq::error_t& e) {
      throw InputError("publish endpoint " + config.publish_endpoint + ": cannot bind: " + e.what());
    }

    const auto started = Clock::now();
    auto status = [&] {
      msg::Status s;
      s.set_state("Idle");
      s.set_version(PLENOPIV_VERSION);
      s.set_uptime_s(std::chrono::duration<double>(Clock::now() - started).count());
      s.set_camera_uri(config.camera_uri);
      s.set_trigger_uri(config.trigger_uri);
      return s;
    };

    daemon::ControlServer server(context, config.control_endpoint, [&](const msg::Request& req) {
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
        default:
          return daemon::error_reply(req.id(), msg::Error::UNAVAILABLE,
                                     "runs and calibration are not built into this plenopivd yet");
      }
    });

    spdlog::info("plenopivd {} ready: control {}, publishing {}", PLENOPIV_VERSION,
                 server.endpoint(), config.publish_endpoint);
    sd_notify(0, "READY=1\nSTATUS=Idle");

    auto last_status = Clock::now();
    while (!g_stop) {
      server.serve_one(100);
      if (Clock::now() - last_status >= std::chrono::seconds(1)) {
        last_status = Clock::now();
        std::string bytes;
        status().SerializeToString(&bytes);
        publisher.send(zmq::str_buffer("status"), zmq::send_flags::sndmore | zmq::send_flags::dontwait);
        publisher.send(zmq::buffer(bytes), zmq::send_flags::dontwait);
      }
    }
    sd_notify(0, "STOPPING=1");
    spdlog::info("plenopivd stopping");
    return 0;
  } catch (const InputError& e) {
    std::cerr << "plenopivd: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "plenopivd: fatal: " << e.what() << "\n";
    return 1;
  }
}
