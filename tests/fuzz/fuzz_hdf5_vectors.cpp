// Fuzz target: the vector field reader (core/io/hdf5_files, group /vectors).
#include "core/io/hdf5_files.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = fuzzing::input_file(data, size, "vectors.h5");
  try {
    const VectorField f = io::read_vector_field_h5(path);
    const std::size_t n = f.grid.count();
    fuzzing::require(f.dx_mm.size() == n && f.dy_mm.size() == n && f.dz_mm.size() == n && f.valid.size() == n,
                     "a vector field whose arrays do not fill its grid");
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  return 0;
}
