// The options several `plenopiv` commands take, spelled one way everywhere: --camera, --threads.
#include "clients/cli/options.hpp"

#include "core/base/errors.hpp"

namespace plenopiv::client {

CLI::Option* add_camera_option(CLI::App* cmd, std::string& camera) {
  return cmd->add_option("--camera", camera, "camera file (YAML: sensor, microlens, main_lens)");
}

CLI::Option* add_threads_option(CLI::App* cmd, int& threads) {
  return cmd->add_option("--threads", threads, "worker threads (0: all cores)")->capture_default_str();
}

std::optional<tbb::global_control> thread_limit(int threads) {
  if (threads < 0) throw InputError("--threads: must be >= 0 (0: all cores), got " + std::to_string(threads));
  std::optional<tbb::global_control> limit;
  if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, threads);
  return limit;
}

}  // namespace plenopiv::client
