// Fuzz target: the --z mini-language of `plenopiv refocus` (clients/cli/depth_list.hpp): depths
// in mm, at most 10000 of them, all finite.
#include <cmath>

#include "clients/cli/depth_list.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<double> depths;
  try {
    depths = client::parse_depths(fuzzing::as_text(data, size));
  } catch (const InputError& e) {
    fuzzing::require_names(e, "--z");
    return 0;
  }
  fuzzing::require(!depths.empty() && depths.size() <= 10000, "a depth list that is empty or over 10000 long");
  for (double z : depths) fuzzing::require(std::isfinite(z), "a depth that is not finite");
  return 0;
}
