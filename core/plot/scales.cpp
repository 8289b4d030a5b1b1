// Axis, colour and arrow scales of the preview plots, as pure functions.
#include "core/plot/scales.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace plenopiv::plot {

double nice_step(double span, int max_intervals) {
  if (!(span > 0) || !std::isfinite(span)) return 1;
  max_intervals = std::max(max_intervals, 1);
  const double raw = span / max_intervals;
  const double decade = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    // A relative tolerance keeps 1000 / 5 at 200, not 500, against rounding in log10 and pow.
    if (m * decade >= raw * (1 - 1e-9)) return m * decade;
  }
  return 10 * decade;
}

SymmetricScale symmetric_scale(double max_abs, int max_intervals_per_side) {
  if (!(max_abs > 0) || !std::isfinite(max_abs)) return {1, 1};
  const double step = nice_step(max_abs, max_intervals_per_side);
  const double limit = std::ceil(max_abs / step * (1 - 1e-9)) * step;
  return {limit, step};
}

std::vector<double> ticks(double lo, double hi, double step) {
  std::vector<double> out;
  if (!(step > 0) || !(hi >= lo)) return out;
  const double eps = 1e-6;
  for (double k = std::ceil(lo / step - eps); k <= std::floor(hi / step + eps); k += 1) out.push_back(k * step);
  return out;
}

namespace {

// Decimals needed to write multiples of `step` exactly (0 for a step >= 1).
int decimals_for(double step) {
  if (!(step > 0) || !std::isfinite(step)) return 0;
  int d = 0;
  while (d < 12 &&
         std::abs(step * std::pow(10.0, d) - std::round(step * std::pow(10.0, d))) > 1e-6 * step * std::pow(10.0, d))
    ++d;
  return d;
}

}  // namespace

std::string tick_label(double value, double step) {
  const int d = decimals_for(step);
  // Values a rounding error away from zero read "0", not "-0".
  if (std::abs(value) < 1e-9 * std::max(step, 1e-300)) value = 0;
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", d, value);
  std::string s = text;
  if (s.find_first_not_of("-0.") == std::string::npos) s = d > 0 ? "0." + std::string(std::size_t(d), '0') : "0";
  return s;
}

double reference_length(double max_value) {
  if (!(max_value > 0) || !std::isfinite(max_value)) return 0;
  const double decade = std::pow(10.0, std::floor(std::log10(max_value)));
  double best = decade;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (std::abs(std::log(m * decade / max_value)) < std::abs(std::log(best / max_value))) best = m * decade;
  }
  return best;
}

std::string quantity_label(double value, const std::string& unit) {
  char text[64];
  std::snprintf(text, sizeof text, "%.6g", value);
  return std::string(text) + " " + unit;
}

double arrow_scale(double max_length, double spacing_mm, double spacing_fraction) {
  if (!(max_length > 0) || !std::isfinite(max_length) || !(spacing_mm > 0)) return 0;
  return spacing_fraction * spacing_mm / max_length;
}

}  // namespace plenopiv::plot
