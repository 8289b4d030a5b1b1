// The --z mini-language of `plenopiv refocus`: object depths in mm as a range or a list.
#pragma once

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "core/base/errors.hpp"

namespace plenopiv::client {

// "start:stop:step" (inclusive) or a comma-separated list, in mm.
inline std::vector<double> parse_depths(const std::string& spec) {
  std::vector<double> out;
  auto number = [&](const std::string& s) {
    std::size_t used = 0;
    double v = 0;
    try {
      v = std::stod(s, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != s.size() || !std::isfinite(v)) {
      throw InputError("--z: '" + s + "' is not a number (give start:stop:step or a,b,c in mm)");
    }
    return v;
  };
  if (std::count(spec.begin(), spec.end(), ':') == 2) {
    const auto a = spec.find(':'), b = spec.find(':', a + 1);
    const double start = number(spec.substr(0, a)), stop = number(spec.substr(a + 1, b - a - 1)),
                 step = number(spec.substr(b + 1));
    if (!(step > 0) || stop < start) throw InputError("--z: " + spec + " needs start <= stop and step > 0");
    const double count = std::floor((stop - start) / step + 1e-9) + 1;
    if (!(count <= 10000)) {
      std::ostringstream n;
      n << count;
      throw InputError("--z: " + spec + " asks for " + n.str() + " depths, more than 10000");
    }
    const int n = int(count);
    for (int k = 0; k < n; ++k) out.push_back(start + k * step);
    return out;
  }
  std::stringstream ss(spec);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(number(item));
  if (out.empty()) throw InputError("--z: no depth given");
  return out;
}

}  // namespace plenopiv::client
