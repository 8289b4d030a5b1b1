// ln and exp of floats in place through SLEEF's deterministic functions in AVX and AVX-512 vectors:
// the same bits as its SSE2 ones ("cinz": no fused multiply-add), more values per instruction.
#pragma once

#include <cstddef>

namespace plenopiv::recon::kernels {

// `n` a multiple of 8 (AVX) or 16 (AVX-512). Call only where the CPU has the instruction set
// (vector_math.cpp checks once): the files that define them are built for it.
void log_avx(float* v, std::size_t n);
void exp_avx(float* v, std::size_t n);
void log_avx512(float* v, std::size_t n);
void exp_avx512(float* v, std::size_t n);

}  // namespace plenopiv::recon::kernels
