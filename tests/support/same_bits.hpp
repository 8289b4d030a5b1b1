// Tests: whether two arrays (vectors, spans, volumes' data) hold the same bits, NaN payloads and
// signed zeros included: what "the same result" means where a build, a cache or a thread count
// must change nothing.
#pragma once

#include <cstring>

namespace plenopiv::testing_support {

template <class Array>
bool same_bits(const Array& x, const Array& y) {
  return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(x[0])) == 0;
}

}  // namespace plenopiv::testing_support
