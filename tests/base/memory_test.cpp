// core/base's memory helpers: the machine's memory against a request, and faulting a block in.
#include <gtest/gtest.h>
#include <oneapi/tbb/global_control.h>

#include <cstddef>
#include <string>
#include <vector>

#include "core/base/big_buffer.hpp"
#include "core/base/errors.hpp"
#include "core/base/memory.hpp"

namespace plenopiv {
namespace {

// Every 4 KB page start inside the block, and nothing else, is written 0, on 1 thread or many.
TEST(FaultInParallel, WritesOneZeroAtEachPageStartOfTheBlockAndNothingOutsideIt) {
  constexpr std::size_t kPage = 4096, kOffset = 3;
  for (const int threads : {1, 2})
    for (const std::size_t bytes : {5 * kPage, 5 * kPage + 7, std::size_t(1)}) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
      std::vector<unsigned char> memory(kOffset + bytes + 2 * kPage, 0xab);
      fault_in_parallel(memory.data() + kOffset, bytes);
      for (std::size_t i = 0; i < memory.size(); ++i) {
        const bool page_start = i >= kOffset && i < kOffset + bytes && (i - kOffset) % kPage == 0;
        ASSERT_EQ(memory[i], page_start ? 0 : 0xab)
            << "byte " << i << " of a block of " << bytes << " at " << threads << " thread(s)";
      }
    }
}

// A BigBuffer of huge blocks (faulted in on allocation) keeps what is written to it as it grows.
TEST(BigBuffer, AHugeBlockHoldsWhatIsWrittenAndKeepsItWhenItGrows) {
  BigBuffer<float> b(std::size_t(3) << 20);  // 12 MB
  for (std::size_t i = 0; i < b.size(); ++i) b[i] = float(i % 1000);
  b.resize(std::size_t(5) << 20);
  for (std::size_t i = 0; i < (std::size_t(3) << 20); i += 4099) ASSERT_EQ(b[i], float(i % 1000)) << i;
}

TEST(RequireMemory, RefusesMoreThanTheMachineHasNamingTheArray) {
  try {
    require_memory(1e18, "the test volume");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("the test volume needs"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(require_memory(1e6, "a small array"));
  EXPECT_THROW(checked_count(-1, 2, 3, 4, "negative"), InputError);
}

}  // namespace
}  // namespace plenopiv
