// plenopiv: the thin client of plenopivd and the offline tools (camera, simulate, process, ...).
#include <iostream>
#include <string>
#include <vector>

#include "clients/cli/commands.hpp"
#include "clients/cli/control_client.hpp"
#include "core/base/errors.hpp"
#include "core/base/isa.hpp"
#include "daemon/logging/logging.hpp"

namespace {

// The exit codes of every command; docs/daemon.md ("Exit codes of the programs") holds the same table.
constexpr const char* kExitCodes =
    "Exit codes:\n"
    "  0        done\n"
    "  1        any other failure (e.g. a run whose setup failed in plenopivd)\n"
    "  2        bad input: a file, value or size that cannot be used (the message names it)\n"
    "  3        no answer: plenopivd did not reply within --timeout, or watch saw no field within --wait\n"
    "  4        plenopivd refused the request (its error code and message are printed)\n"
    "  100-127  the command line (CLI11): 104 a value of the wrong type, 105 a value failing its check,\n"
    "           106 a required option missing, 108 options that exclude each other, 109 an unexpected\n"
    "           argument, 114 the wrong number of values\n"
    "--endpoint, --timeout, --server-key and --client-cert may come before or after the command.\n";

// After a command-line error, says what replaced a spelling the command line still uses.
void hint_renamed_options(int argc, char** argv) {
  const std::vector<std::string> args(argv + 1, argv + argc);
  bool camera_option = false, yaml_positional = false;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--out" || a.rfind("--out=", 0) == 0)
      std::cerr << "plenopiv: --out is spelled -o/--output in every command\n";
    if (a == "--camera" || a.rfind("--camera=", 0) == 0) camera_option = true;
    const bool yaml = a.size() > 5 && (a.ends_with(".yaml") || a.ends_with(".yml"));
    if (yaml && i > 0 && args[i - 1].rfind("-", 0) != 0) yaml_positional = true;
  }
  if (yaml_positional && !camera_option)
    std::cerr << "plenopiv: a camera file is given as --camera FILE in every command\n";
}

}  // namespace

int main(int argc, char** argv) {
  using namespace plenopiv;
  CLI::App app{"plenopiv: control plenopivd and process plenoptic PIV data"};
  app.set_version_flag("--version", std::string(PLENOPIV_VERSION));
  app.require_subcommand(1);
  app.footer(kExitCodes);
  client::ControlOptions control;
  app.add_option("--endpoint", control.endpoint, "plenopivd control endpoint")->capture_default_str();
  app.add_option("--timeout", control.timeout_s, "seconds to wait for plenopivd")->capture_default_str();
  app.add_option("--server-key", control.server_key,
                 "plenopivd's public certificate (.key), for a tcp:// endpoint with CURVE")
      ->check(CLI::ExistingFile);
  app.add_option("--client-cert", control.client_cert,
                 "this client's secret certificate (.key_secret, `plenopiv keys`), for CURVE")
      ->check(CLI::ExistingFile);
  // Options given after the subcommand reach the top level too (`plenopiv status --endpoint ...`).
  app.fallthrough();
  client::add_control_commands(app, control);
  client::add_camera_commands(app);
  client::add_simulate_commands(app);
  client::add_piv_commands(app);
  client::add_recon_commands(app);
  client::add_process_commands(app);
  client::add_calib_commands(app);
  client::add_lightfield_commands(app);
  client::add_run_commands(app, control);
  client::add_keys_commands(app);
  client::add_slurm_commands(app);
  client::add_export_commands(app);

  try {
    setup_logging("plenopiv", "info", LogTarget::console);
    isa();  // a bad PLENOPIV_ISA fails here, before any work
    app.parse(argc, argv);
    return 0;
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    if (code != 0) hint_renamed_options(argc, argv);
    return code;
  } catch (const InputError& e) {
    std::cerr << "plenopiv: " << e.what() << "\n";
    return 2;
  } catch (const std::bad_alloc&) {
    std::cerr << "plenopiv: out of memory: the inputs ask for more than this machine has (check the sizes they "
                 "give: sensor pixels, volume extent and voxel size, counts of particles, rays, depths)\n";
    return 2;
  } catch (const client::ControlError& e) {
    std::cerr << "plenopiv: " << e.what() << "\n";
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "plenopiv: error: " << e.what() << "\n";
    return 1;
  }
}
