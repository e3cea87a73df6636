// The check of every fuzz target (tests/fuzz/input_fuzz_targets.h, bridge_fuzz_targets.h,
// tests/drivers/fuzz_targets.h): a broken promise prints what broke and aborts, so libFuzzer
// keeps the input.
#pragma once

#include <cstdio>
#include <cstdlib>

namespace bodyd::test {

inline void fuzz_check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "fuzz invariant broken: %s\n", what);
    std::abort();
  }
}

}  // namespace bodyd::test
