// libFuzzer entry point of one fuzz target (make fuzz; docs/reliability.md). Built once per
// target with BODYD_FUZZ_TARGET set to the function to call and BODYD_FUZZ_TARGETS_HEADER to the
// header that declares it: input_fuzz_targets.h (the input readers) or bridge_fuzz_targets.h
// (the SlimeVR bridges' decoders).
#if !defined(BODYD_FUZZ_TARGET) || !defined(BODYD_FUZZ_TARGETS_HEADER)
#error "BODYD_FUZZ_TARGET and BODYD_FUZZ_TARGETS_HEADER must be set (tests/fuzz/CMakeLists.txt sets them)"
#endif

#include BODYD_FUZZ_TARGETS_HEADER

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  bodyd::test::BODYD_FUZZ_TARGET(data, size);
  return 0;
}
