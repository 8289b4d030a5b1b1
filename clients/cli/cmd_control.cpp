// `plenopiv status` and `plenopiv devices`: ask plenopivd and print its answer.
#include <iomanip>
#include <iostream>

#include "clients/cli/commands.hpp"
#include "clients/cli/control_client.hpp"

namespace plenopiv::client {
namespace {

// Prints an Error reply and turns it into the exit status 4.
void check(const msg::Reply& reply) {
  if (reply.has_error()) {
    std::cerr << "plenopivd refused: " << msg::Error::Code_Name(reply.error().code()) << ": "
              << reply.error().message() << "\n";
    throw CLI::RuntimeError(4);
  }
}

ControlClient connect(const ControlOptions& options) {
  return ControlClient(options.endpoint,
                       std::chrono::milliseconds(static_cast<long>(options.timeout_s * 1000)));
}

void print_status(const msg::Status& s) {
  std::cout << "state          " << s.state() << (s.message().empty() ? "" : " (" + s.message() + ")")
            << "\n"
            << "version        " << s.version() << "\n"
            << "uptime         " << std::fixed << std::setprecision(1) << s.uptime_s() << " s\n"
            << "camera         " << s.camera_uri() << "\n"
            << "trigger        " << s.trigger_uri() << "\n";
  if (!s.run_id().empty()) {
    std::cout << "run            " << s.run_id() << "\n"
              << "pairs          acquired " << s.pairs_acquired() << ", recorded "
              << s.pairs_recorded() << ", processed " << s.pairs_processed() << ", skipped "
              << s.pairs_skipped() << ", frames lost " << s.frames_lost() << "\n";
  }
}

}  // namespace

void add_control_commands(CLI::App& app, ControlOptions& options) {
  app.add_subcommand("status", "show the daemon's state and counters")->callback([&options] {
    ControlClient client = connect(options);
    msg::Request request;
    request.mutable_status();
    const msg::Reply reply = client.call(request);
    check(reply);
    print_status(reply.status());
  });

  app.add_subcommand("devices", "list the cameras and trigger lines plenopivd can use")
      ->callback([&options] {
        ControlClient client = connect(options);
        msg::Request request;
        request.mutable_list_devices();
        const msg::Reply reply = client.call(request);
        check(reply);
        for (const msg::Device& d : reply.devices().devices()) {
          std::cout << std::left << std::setw(8) << d.kind() << " " << std::setw(28) << d.uri()
                    << " " << d.model() << (d.detail().empty() ? "" : "  (" + d.detail() + ")")
                    << "\n";
        }
        if (reply.devices().devices_size() == 0) std::cout << "no devices found\n";
      });
}

}  // namespace plenopiv::client
