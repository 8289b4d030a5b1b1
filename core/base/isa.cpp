// The instruction set the kernels run: the CPU's best, or the one PLENOPIV_ISA or use_isa names.
#include "core/base/isa.hpp"

#include <atomic>
#include <cstdlib>
#include <string>

#include "core/base/errors.hpp"

namespace plenopiv {
namespace {

void check_runs(Isa isa, const std::string& who) {
  if (isa > best_isa())
    throw InputError(who + ": this CPU cannot run the " + isa_name(isa) + " build (its best is " +
                     isa_name(best_isa()) + ")");
}

std::atomic<Isa>& chosen() {
  static std::atomic<Isa> value = [] {
    const char* named = std::getenv("PLENOPIV_ISA");
    if (!named || !*named) return best_isa();
    for (const Isa isa : {Isa::baseline, Isa::avx2, Isa::avx512})
      if (std::string(named) == isa_name(isa)) {
        check_runs(isa, std::string("PLENOPIV_ISA=") + named);
        return isa;
      }
    throw InputError(std::string("PLENOPIV_ISA=") + named + ": not one of baseline, avx2, avx512");
  }();
  return value;
}

}  // namespace

const char* isa_name(Isa isa) {
  switch (isa) {
    case Isa::baseline:
      return "baseline";
    case Isa::avx2:
      return "avx2";
    case Isa::avx512:
      return "avx512";
  }
  return "?";
}

Isa best_isa() {
  static const Isa best = __builtin_cpu_supports("avx512f") ? Isa::avx512
                          : __builtin_cpu_supports("avx2")  ? Isa::avx2
                                                            : Isa::baseline;
  return best;
}

Isa isa() { return chosen().load(std::memory_order_relaxed); }

void use_isa(Isa isa) {
  check_runs(isa, std::string("use_isa(") + isa_name(isa) + ")");
  chosen().store(isa, std::memory_order_relaxed);
}

}  // namespace plenopiv
