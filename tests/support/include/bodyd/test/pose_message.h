// Whether two pose messages are the same. Header-only: a test that includes this links
// bodyd_protocol.
#pragma once

#include "bodyd/protocol/pose_message.h"

#include <gtest/gtest.h>

#include <cstring>

namespace bodyd::test {

// Every field of the two messages the same, the floats bit for bit (so -0 is not 0); the
// failure names the first field that differs. With compare_publish_time false, publish_t_ns
// (when the message was sent) is not compared.
inline ::testing::AssertionResult same_pose(const protocol::PoseMessage& a, const protocol::PoseMessage& b,
                                            bool compare_publish_time = true) {
  const auto same_bits = [](const auto& x, const auto& y) { return std::memcmp(&x, &y, sizeof(x)) == 0; };
  const auto differs = [&](const std::string& what) {
    return ::testing::AssertionFailure() << what << " differs (seq " << a.seq << " and " << b.seq << ")";
  };
  if (a.seq != b.seq) return differs("seq");
  if (a.t_ns != b.t_ns) return differs("t_ns");
  if (compare_publish_time && a.publish_t_ns != b.publish_t_ns) return differs("publish_t_ns");
  if (a.flags != b.flags) return differs("flags");
  if (a.skeleton_id != b.skeleton_id) return differs("skeleton_id");
  if (a.root_joint != b.root_joint) return differs("root_joint");
  if (a.foot_contact != b.foot_contact) return differs("foot_contact");
  if (!same_bits(a.root_position_m, b.root_position_m)) return differs("root_position_m");
  if (!same_bits(a.root_heading_rad, b.root_heading_rad)) return differs("root_heading_rad");
  if (a.joints.size() != b.joints.size()) return differs("the joint count");
  for (std::size_t i = 0; i < a.joints.size(); ++i) {
    if (!same_bits(a.joints[i].position_m, b.joints[i].position_m)) return differs("joint " + std::to_string(i) + " position");
    if (!same_bits(a.joints[i].rotation_xyzw, b.joints[i].rotation_xyzw))
      return differs("joint " + std::to_string(i) + " rotation");
  }
  return ::testing::AssertionSuccess();
}

}  // namespace bodyd::test
