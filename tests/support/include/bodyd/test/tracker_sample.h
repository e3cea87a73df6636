// One tracker sample, for tests that write their samples by hand, and two sequences of samples
// compared (same_samples). Header-only: a test that includes this links bodyd_motion.
#pragma once

#include "bodyd/motion/tracker.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace bodyd::test {

inline TrackerSample tracker_sample(Role role, std::int64_t t_ns, bool valid, const Vec3& p = Vec3::Zero(),
                                    const Quat& q = Quat::Identity()) {
  TrackerSample s;
  s.role = role;
  s.t_ns = t_ns;
  s.valid = valid;
  s.position_m = p;
  s.rotation = q;
  return s;
}

// Success when `actual` and `expected` have the same length and every sample the same time, role,
// validity, frame, position (and whether it has one) and, with `rotations`, the same rotation
// coefficients, all exactly; otherwise the first difference, by index and field.
inline ::testing::AssertionResult same_samples(const std::vector<TrackerSample>& actual,
                                               const std::vector<TrackerSample>& expected, bool rotations = true) {
  if (actual.size() != expected.size())
    return ::testing::AssertionFailure() << actual.size() << " samples, expected " << expected.size();
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const TrackerSample& a = actual[i];
    const TrackerSample& e = expected[i];
    const auto differs = [i](const char* field) {
      return ::testing::AssertionFailure() << "sample " << i << ": " << field << " differs";
    };
    if (a.t_ns != e.t_ns) return differs("t_ns") << " (" << a.t_ns << " against " << e.t_ns << ")";
    if (a.role != e.role) return differs("role");
    if (a.valid != e.valid) return differs("valid");
    if (a.frame != e.frame) return differs("frame");
    if (a.has_position != e.has_position) return differs("has_position");
    if (a.position_m != e.position_m) return differs("position_m");
    if (rotations && a.rotation.coeffs() != e.rotation.coeffs()) return differs("rotation");
  }
  return ::testing::AssertionSuccess();
}

}  // namespace bodyd::test
