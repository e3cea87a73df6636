// A brief fixed-seed fuzz loop over each decoder (the same targets as the libFuzzer entry
// points): random bytes of every length, and mutations of valid reports (which reach the
// deeper checks). Run longer with libFuzzer: docs/drivers.md.
#include "fuzz_targets.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace bodyd::drivers
