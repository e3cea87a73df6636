// Counts the heap allocations the current thread makes while an AllocationCounter lives. The
// library bodyd_test_alloc_counter replaces the test binary's allocator: malloc and its kin
// (so operator new and Eigen's own allocations are seen), or, in a sanitizer build, where the
// sanitizer owns malloc, every form of operator new.
#pragma once

#include <cstdint>

namespace bodyd::test {

class AllocationCounter {
 public:
  AllocationCounter();
  ~AllocationCounter();
  AllocationCounter(const AllocationCounter&) = delete;
  AllocationCounter& operator=(const AllocationCounter&) = delete;
  [[nodiscard]] std::int64_t count() const;
  // Whether malloc itself is counted (false in a sanitizer build: only operator new is).
  [[nodiscard]] static bool counts_malloc();
};

}  // namespace bodyd::test
