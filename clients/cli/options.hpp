// The options several `plenopiv` commands take, spelled one way everywhere: --camera, --threads.
#pragma once

#include <optional>
#include <string>

#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

namespace plenopiv::client {

// `--camera FILE`: the camera file (YAML: sensor, microlens, main_lens); the caller marks it required
// where the command cannot do without it.
CLI::Option* add_camera_option(CLI::App* cmd, std::string& camera);

// `--threads N`: worker threads of the command's parallel work, N >= 0 (default 0: all cores).
CLI::Option* add_threads_option(CLI::App* cmd, int& threads);

// The limit `--threads` asks for, held for as long as the returned object lives: none for 0 (all
// cores), else at most `threads` workers. A negative count is an InputError naming --threads.
std::optional<tbb::global_control> thread_limit(int threads);

}  // namespace plenopiv::client
