// Single-channel images as row-major arrays (x fastest), the type kernels and files exchange.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/base/big_buffer.hpp"
#include "core/base/memory.hpp"

namespace plenopiv {

template <typename T>
struct Image {
  int width = 0;
  int height = 0;
  HugePageVector<T> pixels;  // row-major, row 0 = first stored row, x fastest

  Image() = default;
  // Sizes are checked against this machine's memory first (InputError naming them).
  Image(int w, int h, T fill = T{})
      : width(w),
        height(h),
        pixels(
            checked_count(w, h, 1, sizeof(T), "an image of " + std::to_string(w) + " x " + std::to_string(h) + " px"),
            fill) {}

  T& at(int x, int y) { return pixels[std::size_t(y) * width + x]; }
  const T& at(int x, int y) const { return pixels[std::size_t(y) * width + x]; }
  std::span<T> row(int y) { return {pixels.data() + std::size_t(y) * width, std::size_t(width)}; }
  std::span<const T> row(int y) const { return {pixels.data() + std::size_t(y) * width, std::size_t(width)}; }
  std::size_t size() const { return pixels.size(); }
  bool empty() const { return pixels.empty(); }
};

using ImageF = Image<float>;
using ImageU16 = Image<std::uint16_t>;

}  // namespace plenopiv
