// Large arrays on transparent huge pages where the kernel offers them: images and volumes
// (HugePageVector, zeroed as std::vector is) and scratch arrays (BigBuffer, not zeroed, faulted in
// on every core).
#pragma once

#include <sys/mman.h>

#include <cstddef>
#include <cstdlib>
#include <new>
#include <utility>
#include <vector>

#include "core/base/memory.hpp"

namespace plenopiv {

// Blocks of 2 MB or more are 2 MB aligned and marked MADV_HUGEPAGE: a 64 MB image then takes 32
// page faults instead of 16 384 (a page fault is the dearer part of a fresh buffer on a virtual
// machine), and the kernels' scattered row accesses miss the TLB less. Where huge pages are off,
// the advice is ignored and nothing else changes. Elements are value-initialised, as by
// std::allocator.
template <typename T>
struct HugePageAllocator {
  using value_type = T;
  static constexpr std::size_t kHugePage = std::size_t(2) << 20;

  HugePageAllocator() = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}

  static bool huge(std::size_t n) { return n * sizeof(T) >= kHugePage; }
  T* allocate(std::size_t n) {
    if (!huge(n)) return static_cast<T*>(::operator new(n * sizeof(T)));
    const std::size_t bytes = (n * sizeof(T) + kHugePage - 1) / kHugePage * kHugePage;
    void* p = std::aligned_alloc(kHugePage, bytes);
    if (!p) throw std::bad_alloc();
    madvise(p, bytes, MADV_HUGEPAGE);
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t n) noexcept {
    if (huge(n)) {
      std::free(p);
    } else {
      ::operator delete(p);
    }
  }
  template <typename U>
  bool operator==(const HugePageAllocator<U>&) const noexcept {
    return true;
  }
};

template <typename T>
using HugePageVector = std::vector<T, HugePageAllocator<T>>;

// As HugePageAllocator, but elements are default-initialised (a float is left as it is: every
// user writes these arrays before reading them, so zeroing 64 MB first is wasted work done on one
// thread).
template <typename T>
struct BigBufferAllocator : HugePageAllocator<T> {
  BigBufferAllocator() = default;
  template <typename U>
  BigBufferAllocator(const BigBufferAllocator<U>&) noexcept {}
  template <typename U>
  struct rebind {
    using other = BigBufferAllocator<U>;
  };
  // A block of 2 MB or more is faulted in at once on the calling arena's threads
  // (fault_in_parallel): these buffers are a reconstruction's or correlation's scratch, allocated
  // on a processing thread and then first touched by whichever thread a loop hands each part to,
  // often one alone (a set-up step, a serial layout), so a fresh frame's faults ran on one core.
  T* allocate(std::size_t n) {
    T* p = HugePageAllocator<T>::allocate(n);
    if (HugePageAllocator<T>::huge(n)) fault_in_parallel(p, n * sizeof(T));
    return p;
  }
  // v(n) and resize(n) default-initialise; v(n, x) still fills with x.
  template <typename U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

template <typename T>
using BigBuffer = std::vector<T, BigBufferAllocator<T>>;

}  // namespace plenopiv
