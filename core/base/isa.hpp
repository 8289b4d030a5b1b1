// Which instruction set the kernels built for several run: AVX-512, AVX2 or baseline x86-64.
#pragma once

namespace plenopiv {

// The builds of the kernels (core/recon/kernels.cpp, core/recon/vector_math.cpp, core/piv), lowest
// first. avx2 needs the CPU's AVX2, avx512 its AVX-512F.
enum class Isa { baseline, avx2, avx512 };

// "baseline", "avx2" or "avx512".
const char* isa_name(Isa isa);

// The highest build this CPU runs.
Isa best_isa();

// The build the kernels run now: the environment variable PLENOPIV_ISA where it is set (to compare
// paths on one machine), else best_isa(). Read at the first call; InputError naming PLENOPIV_ISA for
// a value that is not a build's name or a build this CPU cannot run.
Isa isa();

// Of a kernel's three builds (the same signature), the one isa() names.
template <class F>
F* for_isa(F* avx512, F* avx2, F* baseline) {
  switch (isa()) {
    case Isa::avx512:
      return avx512;
    case Isa::avx2:
      return avx2;
    case Isa::baseline:
      break;
  }
  return baseline;
}

// Makes the kernels run `isa` from now on (the benchmarks' rows per path); InputError where this
// CPU cannot run it.
void use_isa(Isa isa);

}  // namespace plenopiv
