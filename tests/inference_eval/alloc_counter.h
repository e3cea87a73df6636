// Counts heap allocations made by the current thread while a AllocationCounter is alive,
// by replacing the global operator new of the test binary (alloc_counter.cpp).
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
};

}  // namespace bodyd::test
