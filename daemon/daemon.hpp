// plenopivd as an object: its sockets, the run state, the current run, and one handler per request.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <zmq.hpp>

#include "daemon/control_server.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/publisher.hpp"
#include "daemon/run.hpp"
#include "daemon/run_state.hpp"
#include "daemon/zap_authenticator.hpp"
#include "drivers/discovery/device_discovery.hpp"

namespace plenopiv::daemon {

// What a particular plenopivd build brings beyond the registered drivers.
struct DaemonExtensions {
  // Empty: plenoptic_processing() on the configured camera_file (none without one: runs then
  // record raw frames only).
  ProcessFactory processing;
  std::string processing_summary;  // shown in status ("MART + 3D FFT correlation", ...)
};

// Binds the control and publishing sockets (with CURVE and the ZAP handler when configured),
// registers the simulated camera when the config enables it, and marks run folders a previous
// daemon left "recording" as "interrupted". serve() then answers requests until `stop` is set, and
// shutdown() stops the run within its stop bound.
class Daemon {
 public:
  Daemon(DaemonConfig config, const DaemonExtensions& extensions);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Serves control requests and publishes status every second until `stop` is set; feeds systemd's
  // watchdog and status line.
  void serve(const std::atomic<bool>& stop);
  // Stops the current run (if any) and waits until its folder is closed.
  void shutdown();

  msg::Status status() const;
  const std::string& control_endpoint() const { return server_->endpoint(); }
  const std::string& publish_endpoint() const { return publisher_->endpoint(); }
  // Answers one request: the control server's handler (tests/fuzz calls it directly).
  HandlerResult handle(const msg::Request& request);

 private:
  msg::Reply start_run(const msg::StartRun& request);
  msg::Reply stop_run();
  DeferredReply list_devices();
  msg::Reply calibrate(const msg::Calibrate& request);
  void notify_systemd(const msg::Status& status, std::string& last_state, bool watchdog, std::uint64_t watchdog_us);

  DaemonConfig config_;
  std::string processing_;  // what runs' processing does, for status
  ProcessFactory processing_factory_;
  zmq::context_t context_;
  std::unique_ptr<ZapAuthenticator> zap_;  // before the sockets that ask it
  std::unique_ptr<Publisher> publisher_;
  std::unique_ptr<ControlServer> server_;
  RunStateMachine state_;
  std::unique_ptr<Run> run_;
  RunEnvironment environment_;
  std::atomic<std::int64_t> last_progress_ns_{0};
  std::chrono::steady_clock::time_point started_;
  // Device discovery takes about a second: it runs off the control thread, one at a time, and every
  // list_devices request that arrives meanwhile shares its answer.
  std::shared_future<drivers::DiscoveryReport> discovery_;
};

}  // namespace plenopiv::daemon
