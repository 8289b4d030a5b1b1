// The weighting operator as bytes and back, for a cache of operators kept between runs.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "core/base/byte_stream.hpp"
#include "core/base/errors.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::recon {
namespace {

// Written in the layout of this build (structs without padding, or field by field); the format
// number changes with any member.
constexpr char kMagic[8] = {'P', 'L', 'W', 'E', 'I', 'G', 'H', 'T'};
constexpr std::uint32_t kFormat = WeightingOperator::kBytesFormat;

constexpr std::string_view kWhat = "weighting operator bytes";

// A slice's scalars and then its arrays, in the order they are stored: f(scalar) for each scalar
// and g(array) for each array (`Tables`: SliceTables, const or not).
template <typename Tables, typename F, typename G>
void for_each_member(Tables& t, F&& f, G&& g) {
  f(t.z_mm);
  f(t.alpha);
  f(t.magnification);
  f(t.samples);
  for (auto* v : {&t.x_runs, &t.y_runs}) g(*v);
  for (auto* v : {&t.x_segments, &t.y_segments}) g(*v);
  for (auto* v : {&t.x_table, &t.y_table}) g(*v);
  g(t.x_quad_start);
  g(t.x_quad_first);
  g(t.x_quad_weights);
  g(t.y_quad_start);
  g(t.y_quad_first);
  g(t.y_quad_weights);
}

}  // namespace

void WeightingOperator::serialize(std::string& out) const {
  ByteWriter w(out);
  out.append(kMagic, sizeof kMagic);
  w.pod(kFormat);
  w.pod(grid_.shape);
  w.pod(grid_.origin_mm);
  w.pod(grid_.spacing_mm);
  w.pod(width_);
  w.pod(height_);
  w.pod(sensor_);
  w.pod(white_.width);
  w.pod(white_.height);
  w.vec(white_.pixels);
  w.pod(geo_.s_o);
  w.pod(geo_.s_i);
  w.pod(geo_.f_main);
  w.pod(geo_.f_lens);
  w.pod(geo_.aperture);
  w.pod(geo_.pixel_pitch);
  w.pod(geo_.nominal_samples);
  w.pod(geo_.angular_sampling);
  w.pod(geo_.min_pitch);
  w.vec(geo_.lens_x);
  w.vec(geo_.lens_y);
  w.pod(geo_.max_centre_deviation_mm);
  w.pod(std::uint64_t(slices_.size()));
  for (const SliceTables& t : slices_)
    for_each_member(
        t, [&](const auto& v) { w.pod(v); }, [&](const auto& v) { w.vec(v); });
  w.vec(normaliser_);
}

WeightingOperator WeightingOperator::deserialize(std::string_view bytes) {
  ByteReader r(kWhat, bytes.substr(std::min(bytes.size(), sizeof kMagic)));
  if (bytes.size() < sizeof kMagic || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    r.fail("not a weighting operator");
  if (r.pod<std::uint32_t>() != kFormat) r.fail("written in another format");
  WeightingOperator op;
  op.grid_.shape = r.pod<std::array<int, 3>>();
  op.grid_.origin_mm = r.pod<std::array<double, 3>>();
  op.grid_.spacing_mm = r.pod<std::array<double, 3>>();
  op.width_ = r.pod<int>();
  op.height_ = r.pod<int>();
  op.sensor_ = r.pod<optics::SensorSpec>();
  op.white_.width = r.pod<int>();
  op.white_.height = r.pod<int>();
  r.vec(op.white_.pixels);
  op.geo_.s_o = r.pod<double>();
  op.geo_.s_i = r.pod<double>();
  op.geo_.f_main = r.pod<double>();
  op.geo_.f_lens = r.pod<double>();
  op.geo_.aperture = r.pod<double>();
  op.geo_.pixel_pitch = r.pod<double>();
  op.geo_.nominal_samples = r.pod<int>();
  op.geo_.angular_sampling = r.pod<double>();
  op.geo_.min_pitch = r.pod<double>();
  r.vec(op.geo_.lens_x);
  r.vec(op.geo_.lens_y);
  op.geo_.max_centre_deviation_mm = r.pod<double>();
  const auto slices = r.pod<std::uint64_t>();
  if (slices != std::uint64_t(op.grid_.shape[2])) r.fail("slice count does not match the grid");
  // Where each slice starts, found by passing over the arrays; then the slices are copied in
  // parallel: most of the copy's time is the first touch of the tables' fresh pages.
  op.slices_.resize(std::size_t(slices));
  std::vector<std::size_t> start(std::size_t(slices) + 1);
  for (std::size_t z = 0; z < op.slices_.size(); ++z) {
    start[z] = r.at();
    for_each_member(
        op.slices_[z], [&](auto& v) { v = r.pod<std::remove_reference_t<decltype(v)>>(); },
        [&](const auto& v) { r.skip(v); });
  }
  start.back() = r.at();
  tbb::parallel_for(std::size_t(0), op.slices_.size(), [&](std::size_t z) {
    ByteReader slice(kWhat, bytes.substr(sizeof kMagic), start[z]);
    for_each_member(
        op.slices_[z], [&](auto& v) { v = slice.pod<std::remove_reference_t<decltype(v)>>(); },
        [&](auto& v) { slice.vec(v); });
  });
  r.move_to(start.back());
  r.vec(op.normaliser_);
  if (!r.done()) r.fail("bytes left after the operator");
  // Sizes the kernels rely on; the caller's checksum vouches for the values.
  const std::size_t nx = std::size_t(op.grid_.shape[0]), ny = std::size_t(op.grid_.shape[1]);
  bool sound = op.normaliser_.size() == op.grid_.count() && op.white_.width == op.width_ &&
               op.white_.height == op.height_ && op.white_.pixels.size() == op.pixel_count();
  for (const SliceTables& t : op.slices_) {
    sound = sound && t.x_runs.size() == nx && t.y_runs.size() == ny && t.x_quad_start.size() == nx + 1 &&
            t.y_quad_start.size() == ny + 1 && t.x_quad_weights.size() == 4 * t.x_quad_first.size() &&
            t.y_quad_weights.size() == 4 * t.y_quad_first.size() && t.x_quad_start.back() == t.x_quad_first.size() &&
            t.y_quad_start.back() == t.y_quad_first.size();
  }
  if (!sound) r.fail("inconsistent table sizes");
  return op;
}

std::size_t WeightingOperator::bytes() const {
  std::size_t total = white_.pixels.size() * sizeof(float) + normaliser_.size() * sizeof(float);
  for (const SliceTables& t : slices_)
    for_each_member(
        t, [](const auto&) {},
        [&](const auto& v) { total += v.size() * sizeof(typename std::decay_t<decltype(v)>::value_type); });
  return total;
}

}  // namespace plenopiv::recon
