// `plenopiv status` and `plenopiv devices`: ask plenopivd and print its answer.
#include <unistd.h>

#include <google/protobuf/util/json_util.h>

#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <thread>

#include "clients/cli/commands.hpp"
#include "clients/cli/control_client.hpp"

namespace plenopiv::client {
namespace {

// Prints an Error reply and turns it into the exit status 4.
void check(const msg::Reply& reply) {
  if (reply.has_error()) {
    std::cerr << "plenopivd refused: " << msg::Error::Code_Name(reply.error().code()) << ": " << reply.error().message()
              << "\n";
    throw CLI::RuntimeError(4);
  }
}

ControlClient connect(const ControlOptions& options) {
  return ControlClient(options.endpoint, std::chrono::milliseconds(static_cast<long>(options.timeout_s * 1000)),
                       options.security());
}

// One message as JSON on one line: proto field names, every field printed (defaults too), 64-bit
// counters as strings (the proto3 JSON mapping).
std::string json_of(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.always_print_primitive_fields = true;
  options.preserve_proto_field_names = true;
  std::string json;
  const auto status = google::protobuf::util::MessageToJsonString(message, &json, options);
  if (!status.ok()) throw std::runtime_error("JSON of " + message.GetTypeName() + ": " + status.ToString());
  return json;
}

void print_status(const msg::Status& s) {
  std::cout << "state          " << s.state() << (s.message().empty() ? "" : " (" + s.message() + ")") << "\n"
            << "version        " << s.version() << "\n"
            << "kernels        " << s.kernels() << " build\n"
            << "uptime         " << std::fixed << std::setprecision(1) << s.uptime_s() << " s\n"
            << "camera         " << s.camera_uri() << "\n"
            << "trigger        " << s.trigger_uri() << "\n";
  if (!s.run_id().empty()) {
    std::cout << "run            " << s.run_id() << "  " << s.run_dir() << "\n"
              << "pairs          acquired " << s.pairs_acquired() << ", recorded " << s.pairs_recorded()
              << ", processed " << s.pairs_processed() << ", skipped " << s.pairs_skipped() << ", frames lost "
              << s.frames_lost() << "\n";
    for (const msg::StageCounters& c : s.stages()) {
      std::cout << "  " << std::left << std::setw(13) << c.name() << std::right << "processed " << c.processed()
                << ", skipped " << c.skipped() << ", dropped " << c.dropped() << ", queue " << c.queue_depth()
                << ", mean " << std::setprecision(3) << c.mean_time_s() << " s\n";
    }
    for (const msg::LaneCounters& l : s.lanes()) {
      std::cout << "lane " << std::left << std::setw(10) << l.name() << std::right << "tier " << l.tier() << ", "
                << l.policy() << ", queue " << l.queue_depth() << "/" << l.queue_capacity() << ", offered "
                << l.offered() << ", processed " << l.processed() << ", dropped " << l.dropped() << ", failed "
                << l.failed() << ", cancelled " << l.cancelled() << ", in flight " << l.in_flight() << ", mean "
                << std::setprecision(3) << l.mean_time_s() << " s";
      if (l.waited_s() > 0) std::cout << ", waited " << std::setprecision(1) << l.waited_s() << " s for the live lane";
      if (!l.activity().empty()) std::cout << "; " << l.activity();
      std::cout << "\n";
    }
    if (s.has_losses()) {
      const msg::Losses& l = s.losses();
      std::cout << "losses         frames never arrived " << l.frames_never_arrived() << ", discarded "
                << l.frames_discarded() << "; pairs: camera queue " << l.camera_queue_overflow() << ", not read out "
                << l.not_read_out() << ", not recorded at stop " << l.not_recorded_at_stop()
                << "; laser shots abandoned " << l.shots_abandoned() << "\n"
                << "               camera lost: pairs " << l.camera_lost() << ", reconnects " << l.camera_reconnects()
                << "\n"
                << "               live path: queue dropped " << l.live_queue_dropped() << ", failed "
                << l.processing_failed() << ", cancelled " << l.processing_cancelled() << " (on disk)\n";
    }
    if (s.laser_shots_delayed() > 0) {
      std::cout << "laser          " << s.laser_shots_delayed()
                << " shots fired late (the trigger ran late; the laser's interval was kept)\n";
    }
    if (s.bytes_free() > 0) {
      std::cout << "disk free      " << std::setprecision(1) << double(s.bytes_free()) / 1e9 << " GB\n";
    }
    if (s.has_reconstruction()) {
      const msg::ReconstructionWork& r = s.reconstruction();
      const auto live = [](const auto& counts) {
        std::string text;
        for (const auto n : counts) text += (text.empty() ? "" : " ") + std::to_string(n);
        return text;
      };
      // A frame's level, and its tiles' range where they differ (a multi-tap sensor).
      const auto level = [](double median, double lowest, double highest) {
        std::ostringstream text;
        text << std::fixed << std::setprecision(1) << median;
        if (lowest != highest) text << " (tiles " << lowest << " to " << highest << ")";
        return text.str();
      };
      std::cout << "reconstruction pair " << r.pair_index() << ": " << std::setprecision(1)
                << 100 * r.voxel_updates_skipped() << " % of the voxel updates skipped (" << 100 * r.work_pruned()
                << " % of the work pruned); live voxels per iteration of " << r.voxels() << ": A "
                << live(r.live_voxels_a()) << "; B " << live(r.live_voxels_b()) << "; black level taken off A "
                << level(r.black_level_a(), r.black_level_a_lowest(), r.black_level_a_highest()) << ", B "
                << level(r.black_level_b(), r.black_level_b_lowest(), r.black_level_b_highest()) << " counts\n";
    }
    for (const std::string& w : s.warnings()) std::cout << "warning        " << w << "\n";
  }
  std::cout << "processing     " << s.processing() << "\n";
}

}  // namespace

void add_control_commands(CLI::App& app, ControlOptions& options) {
  auto refresh = std::make_shared<bool>(false);
  auto status_json = std::make_shared<bool>(false);
  auto* status = app.add_subcommand("status", "show the daemon's state and counters");
  auto* watch = status->add_flag("-w,--watch", *refresh, "refresh every second until interrupted (on a terminal)");
  status
      ->add_flag("--json", *status_json,
                 "print the Status message as one JSON object (proto field names; 64-bit counters as strings)")
      ->excludes(watch);
  status->callback([&options, refresh, status_json] {
    ControlClient client = connect(options);
    // Refreshing only makes sense on a terminal; piped output gets one report.
    const bool live = *refresh && ::isatty(STDOUT_FILENO);
    do {
      msg::Request request;
      request.mutable_status();
      const msg::Reply reply = client.call(request);
      check(reply);
      if (*status_json) {
        std::cout << json_of(reply.status()) << "\n";
        return;
      }
      if (live) std::cout << "\033[H\033[2J";  // home and clear
      print_status(reply.status());
      std::cout.flush();
      if (live) std::this_thread::sleep_for(std::chrono::seconds(1));
    } while (live);
  });

  auto devices_json = std::make_shared<bool>(false);
  auto* devices = app.add_subcommand("devices", "list the cameras and trigger lines plenopivd can use");
  devices->add_flag("--json", *devices_json,
                    "print a JSON array of devices: uri, kind, model, detail, simulated (true: no hardware)");
  devices->callback([&options, devices_json] {
    ControlClient client = connect(options);
    msg::Request request;
    request.mutable_list_devices();
    const msg::Reply reply = client.call(request);
    check(reply);
    if (*devices_json) {
      std::string array;
      for (const msg::Device& d : reply.devices().devices()) array += (array.empty() ? "" : ",") + json_of(d);
      std::cout << "[" << array << "]\n";
      return;
    }
    for (const msg::Device& d : reply.devices().devices()) {
      std::cout << std::left << std::setw(8) << d.kind() << " " << std::setw(28) << d.uri() << " " << d.model()
                << (d.simulated() ? " [simulated]" : "") << (d.detail().empty() ? "" : "  (" + d.detail() + ")")
                << "\n";
    }
    if (reply.devices().devices_size() == 0) std::cout << "no devices found\n";
  });
}

}  // namespace plenopiv::client
