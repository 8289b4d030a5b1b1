// Fuzz target: the volume reader (core/io/hdf5_files, /volume with origin_mm and spacing_mm).
#include <cmath>

#include "core/io/hdf5_files.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = fuzzing::input_file(data, size, "volume.h5");
  try {
    const Volume v = io::read_volume_h5(path);
    fuzzing::require(v.data.size() == v.grid.count(), "a volume whose data does not fill its grid");
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  return 0;
}
