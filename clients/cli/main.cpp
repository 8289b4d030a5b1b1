// plenopiv: the thin client of plenopivd and the offline tools (camera, later simulate, process).
#include <iostream>

#include "clients/cli/commands.hpp"
#include "clients/cli/control_client.hpp"
#include "core/base/errors.hpp"
#include "daemon/logging/logging.hpp"

int main(int argc, char** argv) {
  using namespace plenopiv;
  CLI::App app{"plenopiv: control plenopivd and process plenoptic PIV data"};
  app.set_version_flag("--version", std::string(PLENOPIV_VERSION));
  app.require_subcommand(1);
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

  try {
    setup_logging("plenopiv", "info", LogTarget::console);
    app.parse(argc, argv);
    return 0;
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
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
