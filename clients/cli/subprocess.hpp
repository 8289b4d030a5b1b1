// Runs another program (sbatch, squeue, scancel) and captures what it prints.
#pragma once

#include <string>
#include <vector>

namespace plenopiv::client {

struct ProgramResult {
  int exit_code = 0;   // the program's exit status; 128 + signal when a signal ended it
  std::string output;  // stdout and stderr, interleaved as written
};

// Runs argv[0] (looked up on PATH) with argv, stdin from /dev/null, and waits for it. InputError
// naming the program when it is not installed (not on PATH); std::runtime_error when it cannot be
// started for another reason.
ProgramResult run_program(const std::vector<std::string>& argv);

}  // namespace plenopiv::client
