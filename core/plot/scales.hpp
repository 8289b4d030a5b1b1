// Axis, colour and arrow scales of the preview plots, as pure functions (tested without drawing).
#pragma once

#include <string>
#include <vector>

namespace plenopiv::plot {

// The "nice" step (1, 2 or 5 times a power of ten) that divides `span` (> 0) into at most
// `max_intervals` (>= 1) intervals with as many as possible; 1 for a span that is not > 0.
double nice_step(double span, int max_intervals);

// A colour scale centred on zero for a signed quantity: -limit .. +limit, ticks every `step`,
// limit a whole number of steps >= the largest magnitude (so the bar spans the data, and its ends
// are round numbers).
struct SymmetricScale {
  double limit = 1;
  double step = 1;
};
// For the largest magnitude `max_abs` (>= 0; 0, NaN or infinity give -1 .. 1), with at most
// `max_intervals_per_side` (>= 1) tick intervals either side of zero.
SymmetricScale symmetric_scale(double max_abs, int max_intervals_per_side = 3);

// The tick values of an axis from `lo` to `hi` (lo <= hi) every `step`: the multiples of `step`
// in [lo, hi] (with a tolerance of a millionth of a step at the ends).
std::vector<double> ticks(double lo, double hi, double step);

// A tick label written out in full with as many decimals as `step` needs ("1500", "-0.25",
// "0"), never in exponent form; -0 reads "0".
std::string tick_label(double value, double step);

// The reference vector's length: the 1, 2 or 5 times a power of ten nearest to `max_value` (> 0) by
// ratio, so the reference is about as long as the longest vector; 0 when `max_value` is not > 0
// (nothing to show).
double reference_length(double max_value);

// "0.5 m/s", "20 mm/s": `value` with the decimals it needs (up to 6 significant digits) and its
// unit.
std::string quantity_label(double value, const std::string& unit);

// The arrow scale, mm of plot per unit of the vector (m/s): the longest vector, `max_length`, is
// drawn `spacing_fraction` of the node spacing `spacing_mm` long; 0 when there is nothing to draw.
double arrow_scale(double max_length, double spacing_mm, double spacing_fraction = 1.2);

}  // namespace plenopiv::plot
