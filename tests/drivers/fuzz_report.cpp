// libFuzzer entry point for the bodyd tracker report decoder (built with -DBODYD_FUZZ=ON, clang).
#include "fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  bodyd::test::fuzz_tracker_report(data, size);
  return 0;
}
