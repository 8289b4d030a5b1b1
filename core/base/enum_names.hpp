// Names of an enum's values as config files and command lines spell them: one table per enum, in
// the enum's order, looked up both ways by these two functions.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <string_view>

#include "core/base/errors.hpp"

namespace plenopiv {

// The name of `value` in `names` (the enum's values 0, 1, ... in order).
template <typename E, std::size_t N>
std::string_view name_in(const std::array<std::string_view, N>& names, E value) {
  return names.at(std::size_t(value));
}

// The value named `name` (exactly); InputError naming `what` (the key or option) and the names
// otherwise.
template <typename E, std::size_t N>
E value_named(const std::array<std::string_view, N>& names, std::string_view name, std::string_view what) {
  std::string list;
  for (std::size_t i = 0; i < N; ++i) {
    if (names[i] == name) return E(i);
    list += (list.empty() ? "" : ", ") + std::string(names[i]);
  }
  throw InputError(std::string(what) + ": expected one of " + list + ", got '" + std::string(name) + "'");
}

}  // namespace plenopiv
