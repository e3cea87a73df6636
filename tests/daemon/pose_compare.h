// What the daemon should publish for a sequence of samples, computed in-process, and the
// comparison of a received pose with it (bit-exact float32).
#pragma once

#include "bodyd/inference/reconstructor.h"
#include "bodyd/protocol/pose_message.h"

#include <gtest/gtest.h>

#include <vector>

namespace bodyd::test {

// One pose per head sample newer than the last pose, as the daemon does (rate 0, no offsets),
// with every sample's time shifted by shift_ns.
inline std::vector<BodyPose> expected_poses(const std::vector<TrackerSample>& samples, Reconstructor& r,
                                            std::int64_t shift_ns = 0) {
  std::vector<BodyPose> out;
  std::int64_t last = INT64_MIN;
  for (TrackerSample s : samples) {
    s.t_ns += shift_ns;
    r.push(s);
    if (s.role != Role::Head || s.t_ns <= last) continue;
    BodyPose body;
    if (!r.reconstruct(s.t_ns, body)) continue;
    last = s.t_ns;
    out.push_back(body);
  }
  return out;
}

inline void expect_pose_equals(const protocol::PoseMessage& got, const BodyPose& want, std::int64_t shift_ns,
                               std::size_t index) {
  SCOPED_TRACE("pose " + std::to_string(index));
  EXPECT_EQ(got.t_ns, want.t_ns);
  (void)shift_ns;
  ASSERT_EQ(got.joints.size(), want.global.positions.size());
  for (std::size_t j = 0; j < got.joints.size(); ++j) {
    const Vec3& p = want.global.positions[j];
    const Quat q = want.global.rotations[j].normalized();
    EXPECT_EQ(got.joints[j].position_m[0], static_cast<float>(p.x())) << "joint " << j;
    EXPECT_EQ(got.joints[j].position_m[1], static_cast<float>(p.y())) << "joint " << j;
    EXPECT_EQ(got.joints[j].position_m[2], static_cast<float>(p.z())) << "joint " << j;
    EXPECT_EQ(got.joints[j].rotation_xyzw[0], static_cast<float>(q.x())) << "joint " << j;
    EXPECT_EQ(got.joints[j].rotation_xyzw[3], static_cast<float>(q.w())) << "joint " << j;
  }
  const std::uint8_t contact = (want.foot_contact[0] ? 1 : 0) | (want.foot_contact[1] ? 2 : 0);
  EXPECT_EQ(got.foot_contact, contact);
  EXPECT_EQ((got.flags & 7u),
            (want.tracker_valid[0] ? 1u : 0u) | (want.tracker_valid[1] ? 2u : 0u) | (want.tracker_valid[2] ? 4u : 0u));
}

}  // namespace bodyd::test
