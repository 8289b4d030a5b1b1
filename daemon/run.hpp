// One run: camera → recorder (every pair) → live pipeline → publisher, on its own threads.
#pragma once

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include "daemon/pipeline.hpp"
#include "daemon/publisher.hpp"
#include "daemon/recorder.hpp"
#include "daemon/run_config.hpp"
#include "daemon/run_state.hpp"
#include "drivers/camera/camera.hpp"

namespace plenopiv::daemon {

// Makes the processing function for a run (it may read the run's reconstruction and correlation
// sections and set up per-run tables). Empty: this daemon has no processing stage, and runs
// record raw frames only.
using ProcessFactory = std::function<ProcessFn(const RunConfig&)>;

struct RunEnvironment {
  std::filesystem::path data_dir;
  std::string default_camera_uri, default_trigger_uri;
  std::filesystem::path camera_file;  // copied into the run folder; empty: none
  RunStateMachine* state = nullptr;
  Publisher* publisher = nullptr;     // null: nothing published
  ProcessFactory processing;
  // Called whenever the run makes progress (a pair recorded, a field published): the heartbeat
  // that the systemd watchdog pings follow.
  std::function<void()> heartbeat;
};

// The state machine must already be Armed for `run_id` (RunStateMachine::start). The constructor
// opens and arms the camera and creates the run folder (InputError on bad URIs or folders), then
// the run starts acquiring on its own thread. It ends by itself after the pair count or duration,
// or when stopped; either way every delivered pair is recorded and the folder closed.
class Run {
 public:
  Run(RunConfig config, std::string run_id, RunEnvironment env);
  ~Run();  // stops and joins
  Run(const Run&) = delete;
  Run& operator=(const Run&) = delete;

  void request_stop() { stop_ = true; }
  bool finished() const { return finished_; }
  void join();
  const std::filesystem::path& dir() const { return recorder_->dir(); }
  const std::string& run_id() const { return run_id_; }
  // Adds this run's counters to a status message.
  void fill_status(msg::Status& status) const;

 private:
  void run();
  void acquire();
  void record(drivers::FramePair pair);

  RunConfig config_;
  std::string run_id_;
  RunEnvironment env_;
  std::unique_ptr<drivers::Camera> camera_;
  std::unique_ptr<Recorder> recorder_;
  ProcessFn process_;
  LiveMailbox mailbox_;
  PipelineStats stats_;
  std::atomic<bool> stop_{false}, finished_{false};
  std::atomic<std::uint64_t> pairs_received_{0};
  std::string acquisition_error_;  // set by the acquisition thread before it ends
  std::thread thread_;
};

}  // namespace plenopiv::daemon
