#include "bodyd/protocol/synthetic.h"

#include <cmath>

namespace bodyd::protocol {

SkeletonMessage synthetic_skeleton() {
  SkeletonMessage s;
  s.names = {"joint_Root", "Hips",       "Spine",      "Chest",      "Neck",       "Head",
             "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L",     "Shoulder_R", "UpperArm_R",
             "LowerArm_R", "Hand_R",     "UpperLeg_L", "LowerLeg_L", "Foot_L",     "Toes_L",
             "UpperLeg_R", "LowerLeg_R", "Foot_R",     "Toes_R"};
  s.parents = {-1, 0, 1, 2, 3, 4, 3, 6, 7, 8, 3, 10, 11, 12, 1, 14, 15, 16, 1, 18, 19, 20};
  s.offsets_m.resize(s.names.size());
  for (std::size_t i = 0; i < s.names.size(); ++i) {
    // Distinct, exactly representable offsets (multiples of 1/64 m).
    s.offsets_m[i] = {static_cast<float>(i % 3) / 64.0f, static_cast<float>(i) / 64.0f,
                      -static_cast<float>(i % 5) / 64.0f};
  }
  s.offsets_m[0] = {0.0f, 0.0f, 0.0f};
  s.skeleton_id = skeleton_id_of(s);
  return s;
}

PoseMessage synthetic_pose(std::uint64_t seq, std::int64_t start_t_ns, std::int64_t period_ns) {
  static const std::uint32_t kSkeletonId = synthetic_skeleton().skeleton_id;
  constexpr std::size_t kJoints = 22;
  PoseMessage p;
  p.seq = seq;
  p.t_ns = start_t_ns + static_cast<std::int64_t>(seq) * period_ns;
  p.publish_t_ns = p.t_ns + 1'000'000;
  p.flags = static_cast<std::uint32_t>(seq % 32);
  p.skeleton_id = kSkeletonId;
  p.root_joint = 1;
  p.foot_contact = static_cast<std::uint8_t>(seq % 4);
  p.joints.resize(kJoints);
  const double s = static_cast<double>(seq % 100000);
  for (std::size_t i = 0; i < kJoints; ++i) {
    const double k = static_cast<double>(i);
    p.joints[i].position_m = {static_cast<float>(0.05 * k + 0.001 * s), static_cast<float>(0.07 * k),
                              static_cast<float>(-0.5 + 0.01 * std::sin(0.1 * s + k))};
    // A rotation about a fixed tilted axis (normalised), by an angle that varies with seq and joint.
    const double half = 0.5 * (0.02 * s + 0.3 * k);
    const double ax = 0.36, ay = 0.48, az = 0.8;  // unit length
    p.joints[i].rotation_xyzw = {static_cast<float>(ax * std::sin(half)), static_cast<float>(ay * std::sin(half)),
                                 static_cast<float>(az * std::sin(half)), static_cast<float>(std::cos(half))};
  }
  p.root_position_m = p.joints[1].position_m;
  p.root_heading_rad = heading_rad_from_rotation(p.joints[1].rotation_xyzw);
  return p;
}

}  // namespace bodyd::protocol
