// Plain values and arrays as bytes in this build's layout, and read back with every length checked:
// the cache files' payloads (weight tables, depth responses).
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "core/base/errors.hpp"

namespace plenopiv {

// Appends to `out`: a value as its bytes, an array as its element count (uint64) then its elements.
class ByteWriter {
 public:
  explicit ByteWriter(std::string& out) : out_(out) {}
  template <typename T>
  void pod(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out_.append(reinterpret_cast<const char*>(&v), sizeof v);
  }
  template <typename T, typename A>
  void vec(const std::vector<T, A>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    pod(std::uint64_t(v.size()));
    if (!v.empty()) out_.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }

 private:
  std::string& out_;
};

// Reads what ByteWriter wrote, from offset `at` of `in`. Any read past the end, or an array count
// larger than the bytes left, throws InputError "<what>: <why>" (`what` names the payload, e.g.
// "weighting operator bytes").
class ByteReader {
 public:
  ByteReader(std::string_view what, std::string_view in, std::size_t at = 0) : what_(what), in_(in), at_(at) {}
  template <typename T>
  T pod() {
    static_assert(std::is_trivially_copyable_v<T>);
    T v;
    take(&v, sizeof v);
    return v;
  }
  template <typename T, typename A>
  void vec(std::vector<T, A>& v) {
    const std::size_t n = count<T>();
    v.resize(n);
    take(v.data(), n * sizeof(T));
  }
  // Passes over an array of v's element type without reading it into v.
  template <typename T, typename A>
  void skip(const std::vector<T, A>&) {
    at_ += count<T>() * sizeof(T);
  }
  std::size_t at() const { return at_; }
  void move_to(std::size_t at) { at_ = at; }
  bool done() const { return at_ == in_.size(); }
  [[noreturn]] void fail(const std::string& why) const { throw InputError(std::string(what_) + ": " + why); }

 private:
  // An array's element count, checked against the bytes left.
  template <typename T>
  std::size_t count() {
    const auto n = pod<std::uint64_t>();
    if (n > (in_.size() - at_) / sizeof(T)) fail("an array runs past the end");
    return std::size_t(n);
  }
  void take(void* dst, std::size_t n) {
    if (n > in_.size() - at_) fail("truncated");
    if (n == 0) return;  // an empty array's data() may be null, which memcpy must not get
    std::memcpy(dst, in_.data() + at_, n);
    at_ += n;
  }
  std::string_view what_;
  std::string_view in_;
  std::size_t at_ = 0;
};

}  // namespace plenopiv
