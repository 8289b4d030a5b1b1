// One run: trigger → camera → recorder (every pair) → processing lanes → publisher, on its own threads.
#pragma once

#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/process/frame_check.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/lanes.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/preview.hpp"
#include "daemon/publisher.hpp"
#include "daemon/run_calibration.hpp"
#include "daemon/run_config.hpp"
#include "daemon/run_state.hpp"
#include "drivers/camera/camera.hpp"
#include "drivers/trigger/shot_joiner.hpp"
#include "drivers/trigger/trigger.hpp"
#include "proto/run_folder.hpp"

namespace plenopiv::daemon {

// What a ProcessFactory calls as a long setup step goes (a depth response measured: minutes at
// the paper's scale): what it is doing and the fraction of it done (0 to 1). The run shows it in
// status, and throws plenopiv::Cancelled there once the run is stopped.
using SetupProgress = std::function<void(const std::string& step, double fraction)>;

// Makes the processing function of one of a run's lanes: the settings of `tier` in the run's
// processing spec (it may set up per-run tables, calling `progress` in a long step), with the
// run's calibration (the one the run folder keeps). Empty: this daemon has no processing stage,
// and runs record raw frames only.
using ProcessFactory = std::function<ProcessFn(const RunConfig&, const RunCalibration&, process::Tier tier,
                                               const SetupProgress& progress)>;

// How long a stop may take, at most, for each of its steps: the camera delivering exposures already
// triggered (drivers::Camera::stop), the recorder writing the pairs delivered before the stop, and
// the processing giving up at its next iteration or pass. Together they keep a stop (and SIGTERM)
// within the unit's TimeoutStopSec.
inline constexpr std::chrono::milliseconds kStopRecordBound{4000};

struct RunEnvironment {
  std::filesystem::path data_dir;
  std::string default_camera_uri, default_trigger_uri;
  std::filesystem::path camera_file;  // copied into the run folder; empty: none
  // The rig's calibration file (lens centres, white correction), read and checked against
  // camera_file at each run start (load_run_calibration), given to the processing and copied
  // into the run folder. Empty: nominal lattice and geometric white image.
  std::filesystem::path calibration_file;
  // What the laser and camera need and allow; the run's rate_hz and dt_s must fit (run_schedule).
  RigTiming timing;
  int processing_nice = 0;  // the lanes' and the preview's threads (DaemonConfig::processing_nice)
  RunStateMachine* state = nullptr;
  Publisher* publisher = nullptr;  // null: nothing published
  ProcessFactory processing;
  // The processing reconstructs frames of camera_file's sensor size (plenoptic_processing): a run
  // whose frames (the camera's sensor, or camera_roi) differ is refused at start.
  bool processing_reads_camera_file = false;
  // Called whenever the run makes progress (a pair recorded, a field published): the heartbeat
  // that the systemd watchdog pings follow.
  std::function<void()> heartbeat;
};

// The state machine must already be Armed for `run_id` (RunStateMachine::start). The constructor
// checks what is quick to check, so that a bad request is refused at once with nothing made: it
// opens the camera and the trigger (the run's URIs, else the daemon's), wires the trigger's camera
// line to the camera (drivers/trigger/camera_wiring.hpp), loads the schedule for rate_hz and dt_s,
// reads the calibration file (InputError naming it when missing, corrupt or made for another
// camera) and checks the disk space (InputError on bad URIs, timing or folders). Then the run's
// own thread sets it up while Armed (the processing: weight tables, seconds at paper scale; status
// says so), creates the run folder and acquires: the trigger fires the laser and camera lines once
// per pair, and each pair gets the laser pulses measured for its shot (ShotJoiner). A setup that
// fails puts the state machine into Error with the reason and makes no folder; a stop while Armed
// ends the run once the current setup step returns, with no folder. The run ends by itself after
// the pair count or duration, or when stopped; either way every delivered pair is recorded, the
// folder closed, and every trigger line driven low (also on errors).
class Run {
 public:
  Run(RunConfig config, std::string run_id, RunEnvironment env);
  ~Run();  // stops and joins
  Run(const Run&) = delete;
  Run& operator=(const Run&) = delete;

  // Stops the run: the trigger and camera stop, in-flight processing is cancelled, the pairs
  // delivered so far are recorded (within kStopRecordBound), and the folder is closed "stopped".
  void request_stop() { stop_ = true; }
  bool finished() const { return finished_; }
  void join();
  // The run folder (it exists once the run has left Armed).
  const std::filesystem::path& dir() const { return dir_; }
  const std::string& run_id() const { return run_id_; }
  // The run's trigger (tests look at a sim trigger's lines through it).
  const drivers::Trigger& trigger() const { return *trigger_; }
  // Adds this run's counters to a status message.
  void fill_status(msg::Status& status) const;

 private:
  void run();
  bool prepare();
  void acquire();
  void record(drivers::FramePair pair);
  void process_lanes();
  void preview_loop();
  void output(const Lane& lane, const drivers::FramePair& pair, ProcessedPair& result);
  std::uint64_t fields_made() const;
  std::vector<msg::LaneCounters> lane_counters() const;
  void attach_shot(drivers::FramePair& pair);
  void check_frames(const drivers::FramePair& pair, const process::FrameRange& range_a,
                    const process::FrameRange& range_b);
  void take_drops();
  void fire_software_trigger(std::uint64_t index);
  void watch_camera(std::chrono::steady_clock::time_point now);
  void begin_outage(const std::string& reason, std::uint64_t made);
  void end_outage(std::uint64_t made);
  void lose_trigger(std::uint64_t index);
  void drain_after_stop();
  void account_for_the_last_triggers();
  void check_write_rate();
  void check_space() const;
  void stop_devices() noexcept;
  msg::Losses losses() const;
  std::uint64_t frames_lost() const;

  RunConfig config_;
  std::string run_id_;
  RunEnvironment env_;
  std::unique_ptr<drivers::Camera> camera_;
  // Declared after the camera: destroyed first, so its lines go low and its connection to a
  // simulated camera's input ends while the camera still exists.
  std::unique_ptr<drivers::Trigger> trigger_;
  drivers::TriggerSource camera_trigger_ = drivers::TriggerSource::External;
  drivers::ShotJoiner joiner_;  // acquisition thread only
  std::filesystem::path dir_;
  RunCalibration calibration_;
  run_folder::Writer::Setup setup_;
  // Set by the run thread once the processing and the folder exist (recorder_ set before it);
  // status reads the recorder only then.
  std::atomic<bool> prepared_{false};
  std::atomic<std::int64_t> setup_started_ns_{0};
  // The setup's long step under way (SetupProgress), when it began and the fraction of it done;
  // empty: none.
  mutable std::mutex setup_mutex_;
  std::string setup_step_;
  std::chrono::steady_clock::time_point setup_step_began_;
  double setup_fraction_ = 0;
  std::unique_ptr<run_folder::Writer> recorder_;
  // The live lane first, then the quality lane when the run has one (make_lanes), and the
  // processing of each (empty when the daemon has none).
  std::vector<std::unique_ptr<Lane>> lanes_;
  std::vector<ProcessFn> processes_;
  // The alignment preview (config_.preview on and a publisher): the newest recorded pair waits in
  // a queue of one; the maker exists once the run is set up.
  std::unique_ptr<LiveMailbox> preview_queue_;
  std::unique_ptr<const PreviewMaker> preview_;
  std::atomic<std::uint64_t> previews_published_{0};
  std::atomic<bool> stop_{false}, finished_{false};
  std::atomic<std::uint64_t> pairs_received_{0};
  std::atomic<std::uint64_t> not_recorded_at_stop_{0};
  // Frames of the run's last triggers that never arrived (account_for_the_last_triggers).
  std::atomic<std::uint64_t> never_arrived_at_end_{0};
  // A camera outage (acquisition thread): when it began, the camera's reconnects then, and why.
  struct Outage {
    std::chrono::steady_clock::time_point since;
    std::uint64_t reconnects = 0;
    std::string reason;
  };
  std::optional<Outage> outage_;
  std::atomic<std::uint64_t> camera_lost_{0};  // triggers with no pair because the camera was lost
  // Triggers the run made (software: fired; external: the trigger's shots) so far, for outages.
  std::uint64_t triggers_made_ = 0;
  // The camera counts triggers from 0 again after a reconnect: the run's index of its trigger 0.
  std::uint64_t trigger_offset_ = 0;
  // The run's triggers recorded or listed with no pair, by index (acquisition thread).
  std::vector<bool> triggers_accounted_;
  void mark_accounted(std::uint64_t trigger_index);
  // One past the highest trigger index (the run's) recorded or listed.
  std::uint64_t triggers_seen() const { return triggers_accounted_.size(); }
  std::uint64_t bytes_per_pair_ = 0;  // raw frames on disk
  std::uint64_t bytes_planned_ = 0;   // the planned pairs' frames and the reserve kept free
  // Bad data met (all-zero or saturated frames): kind -> (count, first pair), for status and manifest.
  mutable std::mutex warnings_mutex_;
  std::string setup_warning_;  // said while Armed (the disk's write rate); in status and the manifest
  std::map<std::string, std::pair<std::uint64_t, std::uint64_t>> warnings_;
  // MART's skipped work on the latest processed pair (its index), for status.
  mutable std::mutex work_mutex_;
  std::optional<std::pair<std::uint64_t, ReconstructionWork>> last_work_;
  std::string acquisition_error_;  // set by the acquisition thread before it ends
  std::thread thread_;
};

}  // namespace plenopiv::daemon
