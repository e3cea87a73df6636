// One tracker sample, for tests that write their samples by hand. Header-only: a test that
// includes this links bodyd_motion.
#pragma once

#include "bodyd/motion/tracker.h"

#include <cstdint>

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

}  // namespace bodyd::test
