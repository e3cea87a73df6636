// libFuzzer entry point for the Razer Hydra report decoder (built with -DBODYD_FUZZ=ON, clang).
#include "fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  bodyd::test::fuzz_hydra_report(data, size);
  return 0;
}
