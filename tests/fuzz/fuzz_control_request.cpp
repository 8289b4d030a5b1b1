// Fuzz target: the control request handler, bytes in and reply out: a control message answered by
// the daemon's own handler (daemon/control_server answer_message over daemon::Daemon::handle), on a
// daemon with the simulated camera (the seed camera) and the test camera, in a scratch data folder.
// Every message gets exactly one reply that parses, with the request's id, and an error reply says
// why; a run it started really runs, and is stopped (a stop_run request) before the next input, so
// that each input is answered by an idle daemon and no run thread outlives the process's statics.
#include <google/protobuf/stubs/logging.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <memory>
#include <thread>

#include "daemon/control_server.hpp"
#include "daemon/daemon.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "tests/drivers/test_camera.hpp"
#include "tests/fuzz/seed_camera.hpp"

using namespace plenopiv;
namespace fs = std::filesystem;

namespace {

daemon::Daemon& the_daemon() {
  static const std::unique_ptr<daemon::Daemon> d = [] {
    testing_support::register_test_camera(drivers::CameraRegistry::instance());
    daemon::DaemonConfig config;
    config.control_endpoint = "ipc://" + (fuzzing::scratch_dir() / "control").string();
    config.publish_endpoint = "ipc://" + (fuzzing::scratch_dir() / "publish").string();
    config.simulation = true;
    config.camera_file = fuzzing::seed_camera_file();
    config.camera_uri = "sim://?rays=50&ppm=0.2";
    config.data_dir = fuzzing::scratch_dir() / "data";
    return std::make_unique<daemon::Daemon>(config, daemon::DaemonExtensions{});
  }();
  return *d;
}

// Finished runs' folders go, so that a long fuzzing session does not fill the scratch folder.
void remove_finished_runs(daemon::Daemon& d) {
  const std::string state = d.status().state();
  if (state != "Idle" && state != "Error") return;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(fuzzing::scratch_dir() / "data", ec)) fs::remove_all(e.path(), ec);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  spdlog::set_level(spdlog::level::off);
  google::protobuf::SetLogHandler(nullptr);  // its complaint about every non-UTF-8 string field
  the_daemon();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  daemon::Daemon& d = the_daemon();
  daemon::Answer answer = daemon::answer_message(data, size, [&](const msg::Request& r) { return d.handle(r); });
  msg::Reply reply = answer.reply;
  if (answer.deferred) {
    fuzzing::require(answer.deferred->wait_for(std::chrono::seconds(30)) == std::future_status::ready,
                     "a deferred reply not ready within 30 s");
    reply = daemon::finish_deferred(answer.reply.id(), *answer.deferred);
  }
  fuzzing::require(reply.kind_case() != msg::Reply::KIND_NOT_SET, "a reply that says nothing");
  msg::Request request;
  if (request.ParseFromArray(data, int(size))) {
    fuzzing::require(reply.id() == request.id(), "a reply with another id than its request");
  }
  if (reply.has_error()) {
    fuzzing::require(!reply.error().message().empty() && reply.error().code() != msg::Error::UNSPECIFIED,
                     "an error reply that does not say what went wrong");
  }
  if (reply.has_run_started()) {
    fuzzing::require(fs::path(reply.run_started().run_dir()).parent_path() == fuzzing::scratch_dir() / "data",
                     "a run folder outside the data folder");
  }
  std::string bytes;
  fuzzing::require(reply.SerializeToString(&bytes), "a reply that does not serialize");
  msg::Reply back;
  fuzzing::require(back.ParseFromString(bytes), "a reply that does not parse");
  const std::string state = d.status().state();
  if (state != "Idle" && state != "Error") {
    msg::Request stop;
    stop.mutable_stop_run();
    const std::string stop_bytes = stop.SerializeAsString();
    (void)daemon::answer_message(stop_bytes.data(), stop_bytes.size(),
                                 [&](const msg::Request& r) { return d.handle(r); });
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (d.status().state() != "Idle" && d.status().state() != "Error") {
      fuzzing::require(std::chrono::steady_clock::now() < deadline, "a run not stopped within 30 s");
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  static int served = 0;
  if (++served % 200 == 0) remove_finished_runs(d);
  return 0;
}
