// Error types that name the culprit: every bad input becomes one of these, never a crash.
#pragma once

#include <stdexcept>
#include <string>

namespace plenopiv {

// Bad input from a user: a config key, a file, an image, a request. The message names the
// culprit (file and key, or argument) and the reason, and is shown to the user as it is.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Work given up because whoever asked for it no longer wants it (a run stopping, a program
// shutting down): not a failure of the work or its input. Thrown from a progress or cancel check.
class Cancelled : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace plenopiv
