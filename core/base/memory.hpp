// How much memory an allocation asks for against what this machine has, checked before allocating.
#pragma once

#include <cstddef>
#include <string>

namespace plenopiv {

// This machine's physical memory in bytes.
double physical_memory_bytes();

// Throws InputError "<what> needs <n> GB, more than this machine's <m> GB of memory" when `bytes`
// exceeds the physical memory (or is negative or not a number): a size that bad input made absurd
// is refused with the estimate instead of ending in std::bad_alloc.
void require_memory(double bytes, const std::string& what);

// Touches every 4 KB page of [p, p + bytes) once (writes a zero byte at its start), the pages
// shared out in parallel over the calling arena's threads: a fresh block's page faults (the kernel
// clearing each page) then run on every core instead of on whichever thread touches the block
// first, often alone. For blocks whose bytes are written before they are read.
void fault_in_parallel(void* p, std::size_t bytes);

// Element count of an array of `a` x `b` x `c` elements of `element_bytes` each, checked with
// require_memory first (negative sizes are refused too); `what` names the array in the message.
std::size_t checked_count(double a, double b, double c, std::size_t element_bytes, const std::string& what);

}  // namespace plenopiv
