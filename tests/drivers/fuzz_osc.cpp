// libFuzzer entry point for the network inputs' decode path: OSC packets (liblo), VRChat and
// VMC messages, tracker-log lines (built with -DBODYD_FUZZ=ON, clang; docs/drivers.md).
#include "fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  bodyd::test::fuzz_osc_input(data, size);
  return 0;
}
