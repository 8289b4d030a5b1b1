// How much memory an allocation asks for against what this machine has, checked before allocating.
#include "core/base/memory.hpp"

#include <unistd.h>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <cmath>
#include <cstdio>

#include "core/base/errors.hpp"

namespace plenopiv {
namespace {

std::string gigabytes(double bytes) {
  char text[64];
  std::snprintf(text, sizeof text, "%.3g GB", bytes / 1e9);
  return text;
}

}  // namespace

double physical_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page = sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page > 0 ? double(pages) * double(page) : 0.0;
}

void require_memory(double bytes, const std::string& what) {
  const double have = physical_memory_bytes();
  if (!(bytes >= 0) || (have > 0 && bytes > have)) {
    throw InputError(what + " needs " + (std::isfinite(bytes) ? gigabytes(bytes) : std::string("unbounded memory")) +
                     ", more than this machine's " + gigabytes(have) + " of memory");
  }
}

void fault_in_parallel(void* p, std::size_t bytes) {
  constexpr std::size_t kPage = 4096, kPagesPerTask = 512;  // a task: one 2 MB huge page
  char* bytes_at = static_cast<char*>(p);
  const std::size_t pages = (bytes + kPage - 1) / kPage;
  // Isolated: a thread waiting here takes none of its caller's other tasks, which may hold a lock
  // or a per-thread slot (an allocation can happen inside a task).
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pages, kPagesPerTask),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t page = r.begin(); page < r.end(); ++page) bytes_at[page * kPage] = 0;
                      });
  });
}

std::size_t checked_count(double a, double b, double c, std::size_t element_bytes, const std::string& what) {
  if (!(a >= 0) || !(b >= 0) || !(c >= 0)) {
    throw InputError(what + ": a negative size (" + std::to_string(a) + " x " + std::to_string(b) + " x " +
                     std::to_string(c) + ")");
  }
  const double n = a * b * c;
  require_memory(n * double(element_bytes), what);
  return std::size_t(n);
}

}  // namespace plenopiv
