// libFuzzer entry point of one SlimeVR-bridge fuzz target (make fuzz; bridge_fuzz_targets.h).
// Built once per target with BODYD_FUZZ_TARGET set to the function to call.
#include "bridge_fuzz_targets.h"

#ifndef BODYD_FUZZ_TARGET
#error "BODYD_FUZZ_TARGET must name the target function (tests/fuzz/CMakeLists.txt sets it)"
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  bodyd::test::BODYD_FUZZ_TARGET(data, size);
  return 0;
}
