// Tests: the message of the InputError a call throws.
#pragma once

#include <string>

#include "core/base/errors.hpp"

namespace plenopiv::testing_support {

// The message of the InputError `f` throws, "" if it throws none (any other exception goes on).
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace plenopiv::testing_support
