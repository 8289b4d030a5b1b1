// Settings of the multi-pass correlation: passes (window, overlap), validation, dt; from YAML.
#include "core/piv/settings.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <string_view>

#include "core/base/enum_names.hpp"
#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"

namespace plenopiv::piv {
namespace {

// `key` of `map` given once for all three axes or as [x, y, z]; the map's error naming the key
// otherwise (`shape`: what to give, `type`: a value that is not a T).
template <typename T>
std::array<T, 3> per_axis(const YamlMap& map, std::string_view key, const std::string& shape, const std::string& type) {
  const YAML::Node v = map.node()[std::string(key)];
  try {
    if (v.IsScalar()) {
      const T x = v.as<T>();
      return {x, x, x};
    }
    if (v.IsSequence() && v.size() == 3) return {v[0].as<T>(), v[1].as<T>(), v[2].as<T>()};
  } catch (const YAML::Exception&) {
    map.fail(key, type);
  }
  map.fail(key, shape);
}

}  // namespace

void check(const CorrelationSettings& s, const std::string& source) {
  auto fail = [&](const std::string& what) { throw InputError(source + ": " + what); };
  if (s.passes.empty()) fail("passes: at least one pass is needed");
  for (std::size_t p = 0; p < s.passes.size(); ++p) {
    const auto& pass = s.passes[p];
    const std::string at = "passes[" + std::to_string(p) + "]";
    for (int a = 0; a < 3; ++a)
      if (pass.window[a] < 4)
        fail(at + ".window: every size must be >= 4 voxels, got " + std::to_string(pass.window[a]));
    if (!(pass.overlap_percent >= 0 && pass.overlap_percent < 100))
      fail(at + ".overlap_percent: must be in [0, 100), got " + std::to_string(pass.overlap_percent));
    if (pass.depth_margin < 0 || pass.depth_margin > pass.window[2])
      fail(at + ".depth_margin: must be 0 to the window's depth (" + std::to_string(pass.window[2]) + " voxels), got " +
           std::to_string(pass.depth_margin));
  }
  if (!(s.median.threshold > 0)) fail("median.threshold: must be > 0");
  if (!(s.median.epsilon > 0)) fail("median.epsilon_voxel: must be > 0");
  if (s.median.radius < 1 || s.median.radius > 3) fail("median.radius: must be 1, 2 or 3");
  if (s.predictor_smoothing < 0 || s.predictor_smoothing > 4)
    fail("predictor_smoothing: must be 0 to 4, got " + std::to_string(s.predictor_smoothing));
  if (s.final_smoothing < 0 || s.final_smoothing > 4)
    fail("final_smoothing: must be 0 to 4, got " + std::to_string(s.final_smoothing));
  if (s.uncertainty_stride < 1 || s.uncertainty_stride > 4)
    fail("uncertainty_stride: must be 1 to 4 nodes, got " + std::to_string(s.uncertainty_stride));
  if (s.depth_prefilter < 0 || s.depth_prefilter > 8)
    fail("depth_prefilter: must be 0 to 8, got " + std::to_string(s.depth_prefilter));
  if (s.depth_prefilter > 0 && !s.prefilter)
    fail("depth_prefilter: " + std::to_string(s.depth_prefilter) +
         " depth passes follow the prefilter, which is off (prefilter: false); set it to 0 or turn the prefilter on");
  if (!(s.signal_threshold >= 0)) fail("signal_threshold: must be >= 0");
  if (!(s.intensity_threshold_of_mean >= 0 && s.intensity_threshold_of_mean <= 100))
    fail("intensity_threshold_of_mean: must be in [0, 100] (times the volume's mean), got " +
         std::to_string(s.intensity_threshold_of_mean));
  if (!(s.spectral_whitening >= 0 && s.spectral_whitening <= 1))
    fail("spectral_whitening: must be in [0, 1], got " + std::to_string(s.spectral_whitening));
  for (int a = 0; a < 3; ++a)
    if (!(s.whitened_peak_sigma_voxel[std::size_t(a)] >= 0.5 && s.whitened_peak_sigma_voxel[std::size_t(a)] <= 8))
      fail("whitened_peak_sigma_voxel: each must be in [0.5, 8] voxels, got " +
           std::to_string(s.whitened_peak_sigma_voxel[std::size_t(a)]));
  if (s.final_peak_search == FinalPeakSearch::near_predictor && s.passes.back().depth_margin > 0)
    fail("final_peak_search: near_predictor needs a final pass without depth_margin (passes[" +
         std::to_string(s.passes.size() - 1) + "] has " + std::to_string(s.passes.back().depth_margin) +
         "; its normalisation needs every shift)");
  if (!(s.dt_s > 0)) fail("dt_s: must be > 0, got " + std::to_string(s.dt_s));
}

int PassSettings::step(int axis) const {
  return std::max(1, int(std::lround(window[std::size_t(axis)] * (1 - overlap_percent / 100))));
}

std::string_view name_of(PredictorBase base) { return name_in(kPredictorBaseNames, base); }
std::string_view name_of(Interpolation interpolation) { return name_in(kInterpolationNames, interpolation); }
std::string_view name_of(FinalPeakSearch search) { return name_in(kFinalPeakSearchNames, search); }

PredictorBase predictor_base_named(std::string_view name, std::string_view what) {
  return value_named<PredictorBase>(kPredictorBaseNames, name, what);
}
Interpolation interpolation_named(std::string_view name, std::string_view what) {
  return value_named<Interpolation>(kInterpolationNames, name, what);
}
FinalPeakSearch final_peak_search_named(std::string_view name, std::string_view what) {
  return value_named<FinalPeakSearch>(kFinalPeakSearchNames, name, what);
}

std::vector<PassSettings> parse_passes(const std::string& text) {
  std::vector<PassSettings> passes;
  std::stringstream all(text);
  std::string item;
  auto bad = [&](const std::string& why) {
    throw InputError("--passes: '" + item + "': " + why +
                     " (expected WxHxD@overlap or W@overlap, optionally +depth_margin, e.g. "
                     "32@50,16@50+4,16x16x32@75)");
  };
  while (std::getline(all, item, ',')) {
    const auto at = item.find('@');
    if (at == std::string::npos) bad("missing @overlap");
    const auto plus = item.find('+', at);
    const std::size_t overlap_end = plus == std::string::npos ? item.size() : plus;
    PassSettings pass;
    try {
      std::size_t used = 0;
      pass.overlap_percent = std::stod(item.substr(at + 1, overlap_end - at - 1), &used);
      if (used != overlap_end - at - 1) bad("trailing characters after the overlap");
      if (plus != std::string::npos) {
        pass.depth_margin = std::stoi(item.substr(plus + 1), &used);
        if (used != item.size() - plus - 1) bad("the depth margin is not a whole number");
      }
      std::stringstream sizes(item.substr(0, at));
      std::string size;
      std::vector<int> w;
      while (std::getline(sizes, size, 'x')) {
        w.push_back(std::stoi(size, &used));
        if (used != size.size()) bad("not a whole number: " + size);
      }
      if (w.size() == 1)
        pass.window = {w[0], w[0], w[0]};
      else if (w.size() == 3)
        pass.window = {w[0], w[1], w[2]};
      else
        bad("give one size or three");
    } catch (const std::logic_error&) {
      bad("not a number");
    }
    passes.push_back(pass);
  }
  CorrelationSettings s;
  s.passes = passes;
  check(s, "--passes");
  return passes;
}

CorrelationSettings correlation_settings_from(const YamlMap& root) {
  root.reject_unknown({"passes", "median", "signal_threshold", "dt_s", "fft_planning", "prefilter", "depth_prefilter",
                       "predictor", "predictor_smoothing", "intensity_threshold_of_mean", "final_smoothing",
                       "uncertainty", "uncertainty_stride", "early_interpolation", "spectral_whitening",
                       "whitened_peak_sigma_voxel", "final_peak_search"});
  CorrelationSettings s;
  if (root.has("passes")) {
    const YAML::Node list = root.node()["passes"];
    if (!list.IsSequence()) root.fail("passes", "must be a list of {window, overlap_percent, depth_margin}");
    s.passes.clear();
    for (std::size_t p = 0; p < list.size(); ++p) {
      const std::string key = "passes[" + std::to_string(p) + "]";
      const YamlMap pass(list[p], root.source(), root.path().empty() ? key : root.path() + "." + key);
      pass.reject_unknown({"window", "overlap_percent", "depth_margin"});
      PassSettings ps;
      ps.window = per_axis<int>(pass, "window", "must be a size or [x, y, z]", "sizes must be whole numbers");
      ps.overlap_percent = pass.number_or("overlap_percent", 0);
      const long long margin = pass.integer_or("depth_margin", 0);
      if (margin < 0 || margin > ps.window[2])
        pass.fail("depth_margin", "must be 0 to the window's depth (" + std::to_string(ps.window[2]) + " voxels)");
      ps.depth_margin = int(margin);
      s.passes.push_back(ps);
    }
  }
  if (auto m = root.optional_map("median")) {
    m->reject_unknown({"threshold", "epsilon_voxel", "radius"});
    s.median.threshold = m->number_or("threshold", s.median.threshold);
    s.median.epsilon = m->number_or("epsilon_voxel", s.median.epsilon);
    s.median.radius = m->integer_in("radius", s.median.radius, 1, 3);
  }
  s.signal_threshold = float(root.number_or("signal_threshold", s.signal_threshold));
  s.dt_s = root.number_or("dt_s", s.dt_s);
  s.fft_planning = root.choice_or("fft_planning", {"estimate", "measure"}, "estimate") == "measure"
                       ? FftPlanning::measure
                       : FftPlanning::estimate;
  s.intensity_threshold_of_mean = root.number_or("intensity_threshold_of_mean", s.intensity_threshold_of_mean);
  s.prefilter = root.boolean_or("prefilter", s.prefilter);
  s.depth_prefilter = root.integer_in("depth_prefilter", s.depth_prefilter, 0, 8);
  s.predictor = predictor_base_named(
      root.choice_or("predictor", kPredictorBaseNames, std::string(name_of(s.predictor))), "predictor");
  s.predictor_smoothing = root.integer_in("predictor_smoothing", s.predictor_smoothing, 0, 4);
  s.final_smoothing = root.integer_in("final_smoothing", s.final_smoothing, 0, 4);
  s.uncertainty = root.boolean_or("uncertainty", s.uncertainty);
  s.uncertainty_stride = root.integer_in("uncertainty_stride", s.uncertainty_stride, 1, 4);
  s.early_interpolation = interpolation_named(
      root.choice_or("early_interpolation", kInterpolationNames, std::string(name_of(s.early_interpolation))),
      "early_interpolation");
  s.spectral_whitening = root.number_or("spectral_whitening", s.spectral_whitening);
  if (root.has("whitened_peak_sigma_voxel"))
    s.whitened_peak_sigma_voxel = per_axis<double>(
        root, "whitened_peak_sigma_voxel", "must be a width or [x, y, z], voxels", "widths must be numbers, voxels");
  s.final_peak_search = final_peak_search_named(
      root.choice_or("final_peak_search", kFinalPeakSearchNames, std::string(name_of(s.final_peak_search))),
      "final_peak_search");
  check(s, root.source());
  return s;
}

CorrelationSettings load_correlation_settings(const std::filesystem::path& path) {
  return correlation_settings_from(YamlMap(load_yaml_file(path), path.string()));
}

}  // namespace plenopiv::piv
