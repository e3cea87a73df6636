// A brief fixed-seed fuzz loop over each decoder (the same targets as the libFuzzer entry
// points): random bytes of every length, and mutations of valid reports (which reach the
// deeper checks). Run longer with libFuzzer: docs/drivers.md.
#include "fuzz_targets.h"

#include <gtest/gtest.h>
#include <lo/lo.h>

#include <random>
#include <vector>

namespace bodyd::drivers {
namespace {

template <class Target>
void fuzz_loop(Target target, const std::vector<std::uint8_t>& seed_input, int iterations) {
  std::mt19937_64 rng(20240505);  // fixed: a failure reproduces
  std::vector<std::uint8_t> buf;
  for (int i = 0; i < iterations; ++i) {
    if (i % 2 == 0) {
      buf.resize(rng() % 80);
      for (auto& b : buf) b = static_cast<std::uint8_t>(rng());
    } else {
      buf = seed_input;
      const int flips = 1 + static_cast<int>(rng() % 4);
      for (int f = 0; f < flips; ++f) buf[rng() % buf.size()] = static_cast<std::uint8_t>(rng());
      if (rng() % 8 == 0) buf.resize(rng() % (buf.size() + 8));
    }
    target(buf.data(), buf.size());
  }
}

TEST(DecoderFuzz, TrackerReport) {
  TrackerReport r;
  r.valid = true;
  r.role = Role::Head;
  r.position_m = Vec3(0.1, 1.6, -0.2);
  std::array<std::uint8_t, kTrackerReportSize> valid{};
  ASSERT_EQ(encode_tracker_report(r, valid), ReportError::None);
  fuzz_loop(test::fuzz_tracker_report, {valid.begin(), valid.end()}, 200000);
}

TEST(DecoderFuzz, HydraReport) {
  HydraReport r;
  r.controllers[0].valid = r.controllers[1].valid = true;
  const auto valid = encode_hydra_report(r, HydraOptions{});
  fuzz_loop(test::fuzz_hydra_report, {valid.begin(), valid.end()}, 200000);
}

// Seeds: a VRChat bundle of three poses and a VMC message, built by liblo.
TEST(DecoderFuzz, OscInput) {
  auto pose = [](std::initializer_list<float> values) {
    lo_message m = lo_message_new();
    for (float v : values) lo_message_add_float(m, v);
    return m;
  };
  lo_bundle b = lo_bundle_new(LO_TT_IMMEDIATE);
  lo_bundle_add_message(b, "/tracking/vrsystem/head/pose", pose({0, 1.6f, 0, 10, 20, 30}));
  lo_bundle_add_message(b, "/tracking/vrsystem/leftwrist/pose", pose({-0.3f, 1, 0, 0, 90, 0}));
  lo_bundle_add_message(b, "/tracking/vrsystem/rightwrist/pose", pose({0.3f, 1, 0, 0, 0, 90}));
  std::size_t n = 0;
  void* data = lo_bundle_serialise(b, nullptr, &n);
  const std::vector<std::uint8_t> vrchat(static_cast<std::uint8_t*>(data), static_cast<std::uint8_t*>(data) + n);
  std::free(data);
  lo_bundle_free_recursive(b);
  lo_message m = lo_message_new();
  lo_message_add_string(m, "LHR-1");
  for (float v : {0.5f, 1.0f, 2.0f, 0.0f, 0.0f, 0.0f, 1.0f}) lo_message_add_float(m, v);
  data = lo_message_serialise(m, "/VMC/Ext/Con/Pos", nullptr, &n);
  const std::vector<std::uint8_t> vmc(static_cast<std::uint8_t*>(data), static_cast<std::uint8_t*>(data) + n);
  std::free(data);
  lo_message_free(m);
  fuzz_loop(test::fuzz_osc_input, vrchat, 50000);
  fuzz_loop(test::fuzz_osc_input, vmc, 50000);
  const std::string line = "123,head,1,0.1,1.6,-0.2,0,0,0,1\n";
  fuzz_loop(test::fuzz_osc_input, {line.begin(), line.end()}, 20000);
}

}  // namespace
}  // namespace bodyd::drivers
