#include "bodyd/motion/humanoid.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace bodyd {
namespace {

// Where each joint's local axes point in the T-pose facing +Z (left +X, up +Y, forward +Z),
// read off the bundled data (every clip's frames agree to a few degrees): the bone to the
// child runs along local +X for the spine and the left limbs, along -X for the right limbs;
// the elbows and knees bend about local Y (flexion negative at the elbow, positive at the
// knee), the Hips' +Z is the body's forward (the pose message's root_heading_rad uses it).
enum class Frame {
  Root,   // identity
  Hips,   // X up, Y right, Z forward
  Spine,  // X up, Y forward, Z left       (Spine, Chest, Neck, Head)
  ArmL,   // X left, Y up, Z forward       (Shoulder_L .. Hand_L)
  ArmR,   // X left, Y down, Z backward    (Shoulder_R .. Hand_R; the bone runs along -X)
  LegL,   // X down, Y left, Z forward     (UpperLeg_L, LowerLeg_L)
  LegR,   // X up, Y left, Z backward      (UpperLeg_R, LowerLeg_R; the bone runs along -X)
  FootL,  // LegL pitched so the bone points forward and kRestFootPitchDeg down
  FootR,
  ToesL,  // LegL pitched so the bone points forward and kRestToesPitchDeg down
  ToesR,
};

struct JointSpec {
  std::string_view name;
  std::string_view parent;  // empty for the root
  Frame frame;
};

constexpr JointSpec kJoints[] = {
    {"joint_Root", "", Frame::Root},
    {"Hips", "joint_Root", Frame::Hips},
    {"Spine", "Hips", Frame::Spine},
    {"Chest", "Spine", Frame::Spine},
    {"Neck", "Chest", Frame::Spine},
    {"Head", "Neck", Frame::Spine},
    {"Shoulder_L", "Chest", Frame::ArmL},
    {"UpperArm_L", "Shoulder_L", Frame::ArmL},
    {"LowerArm_L", "UpperArm_L", Frame::ArmL},
    {"Hand_L", "LowerArm_L", Frame::ArmL},
    {"Shoulder_R", "Chest", Frame::ArmR},
    {"UpperArm_R", "Shoulder_R", Frame::ArmR},
    {"LowerArm_R", "UpperArm_R", Frame::ArmR},
    {"Hand_R", "LowerArm_R", Frame::ArmR},
    {"UpperLeg_L", "Hips", Frame::LegL},
    {"LowerLeg_L", "UpperLeg_L", Frame::LegL},
    {"Foot_L", "LowerLeg_L", Frame::FootL},
    {"Toes_L", "Foot_L", Frame::ToesL},
    {"UpperLeg_R", "Hips", Frame::LegR},
    {"LowerLeg_R", "UpperLeg_R", Frame::LegR},
    {"Foot_R", "LowerLeg_R", Frame::FootR},
    {"Toes_R", "Foot_R", Frame::ToesR},
};

// A rotation from the images of the local X, Y, Z axes.
Quat from_axes(const Vec3& x, const Vec3& y, const Vec3& z) {
  Mat3 m;
  m.col(0) = x;
  m.col(1) = y;
  m.col(2) = z;
  return Quat(m).normalized();
}

Quat global_rest_rotation(Frame frame) {
  const Vec3 l = Vec3::UnitX(), u = Vec3::UnitY(), f = Vec3::UnitZ();
  // Pitching a leg frame about the left axis by (pitch - 90 degrees) turns its bone (down)
  // to point forward and `pitch` below horizontal, on both sides.
  auto pitched = [&](const Quat& leg, double pitch_deg) {
    return (Quat(Eigen::AngleAxisd((pitch_deg - 90.0) * M_PI / 180.0, l)) * leg).normalized();
  };
  const Quat leg_l = from_axes(-u, l, f);
  const Quat leg_r = from_axes(u, l, -f);
  switch (frame) {
    case Frame::Root: return Quat::Identity();
    case Frame::Hips: return from_axes(u, -l, f);
    case Frame::Spine: return from_axes(u, f, l);
    case Frame::ArmL: return from_axes(l, u, f);
    case Frame::ArmR: return from_axes(l, -u, -f);
    case Frame::LegL: return leg_l;
    case Frame::LegR: return leg_r;
    case Frame::FootL: return pitched(leg_l, kRestFootPitchDeg);
    case Frame::FootR: return pitched(leg_r, kRestFootPitchDeg);
    case Frame::ToesL: return pitched(leg_l, kRestToesPitchDeg);
    case Frame::ToesR: return pitched(leg_r, kRestToesPitchDeg);
  }
  return Quat::Identity();
}

}  // namespace

bool make_rest_pose(const Skeleton& skeleton, RestPose& out, std::string& out_error) {
  if (std::string e = skeleton.validate(); !e.empty()) {
    out_error = "rest pose: invalid skeleton: " + e;
    return false;
  }
  const auto n = static_cast<size_t>(skeleton.size());
  std::vector<Quat> global(n, Quat::Identity());
  std::vector<bool> known(n, false);
  for (const JointSpec& spec : kJoints) {
    const int j = skeleton.find(spec.name);
    if (j < 0) {
      out_error = fmt::format("rest pose: the skeleton has no joint '{}' (the reference T-pose knows the joints of "
                              "the bundled motion data's skeleton, docs/protocol.md)", spec.name);
      return false;
    }
    const int p = skeleton.parents[static_cast<size_t>(j)];
    const std::string_view parent_name = p < 0 ? std::string_view() : std::string_view(skeleton.names[static_cast<size_t>(p)]);
    if (parent_name != spec.parent) {
      out_error = fmt::format("rest pose: joint '{}' has parent '{}', expected '{}'", spec.name,
                              p < 0 ? "(none)" : parent_name, spec.parent.empty() ? "(none)" : spec.parent);
      return false;
    }
    global[static_cast<size_t>(j)] = global_rest_rotation(spec.frame);
    known[static_cast<size_t>(j)] = true;
  }
  // Joints beyond the humanoid's (none in the bundled skeleton) keep their parent's frame.
  for (size_t j = 0; j < n; ++j)
    if (!known[j] && skeleton.parents[j] >= 0) global[j] = global[static_cast<size_t>(skeleton.parents[j])];

  out.offsets = skeleton.offsets;
  out.rotations.assign(n, Quat::Identity());
  for (size_t j = 0; j < n; ++j) {
    const int p = skeleton.parents[j];
    out.rotations[j] = p < 0 ? global[j] : (global[static_cast<size_t>(p)].conjugate() * global[j]).normalized();
  }
  const auto hips = static_cast<size_t>(skeleton.find("Hips"));
  out.offsets[0] = Vec3::Zero();
  out.offsets[hips] = Vec3::Zero();
  Pose pose{out.rotations, out.offsets};
  forward_kinematics(skeleton, pose, out.global);
  const double toes_y = std::min(out.global.positions[static_cast<size_t>(skeleton.find("Toes_L"))].y(),
                                 out.global.positions[static_cast<size_t>(skeleton.find("Toes_R"))].y());
  // joint_Root's rest rotation is the identity, so its frame is the world's.
  out.offsets[hips] = Vec3(0.0, kRestToesHeightM - toes_y, 0.0);
  pose.local_translations = out.offsets;
  forward_kinematics(skeleton, pose, out.global);
  return true;
}

bool make_unity_rig(const Skeleton& skeleton, UnityRig& out, std::string& out_error) {
  RestPose rest;
  if (!make_rest_pose(skeleton, rest, out_error)) return false;
  // Unity's humanoid faces its +Z, which is bodyd's -Z: the reference is the T-pose turned
  // half a turn about +Y.
  const Quat turn(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));
  for (size_t b = 0; b < kHumanoidBones.size(); ++b) {
    const int j = skeleton.find(kHumanoidBones[b].bodyd);
    out.joint[b] = j;  // make_rest_pose checked it exists
    out.parent[b] = -1;
    const int pj = skeleton.parents[static_cast<size_t>(j)];
    for (size_t a = 0; a < b; ++a)
      if (out.joint[a] == pj) out.parent[b] = static_cast<int>(a);
    const Vec3 from = out.parent[b] < 0 ? Vec3::Zero() : rest.global.positions[static_cast<size_t>(pj)];
    out.tpose_local_position[b] = unity_from_bodyd(turn * (rest.global.positions[static_cast<size_t>(j)] - from));
    out.tpose_global_inverse[b] = (turn * rest.global.rotations[static_cast<size_t>(j)]).conjugate().normalized();
  }
  return true;
}

void retarget_to_unity(const UnityRig& rig, const GlobalPose& global, UnityPose& out) {
  std::array<Quat, kHumanoidBones.size()> g;
  for (size_t b = 0; b < kHumanoidBones.size(); ++b) {
    const auto j = static_cast<size_t>(rig.joint[b]);
    g[b] = unity_from_bodyd(Quat((global.rotations[j] * rig.tpose_global_inverse[b]).normalized()));
    const int p = rig.parent[b];
    out.local_rotations[b] = p < 0 ? g[b] : (g[static_cast<size_t>(p)].conjugate() * g[b]).normalized();
    out.local_positions[b] = p < 0 ? unity_from_bodyd(global.positions[j]) : rig.tpose_local_position[b];
  }
}

void unity_forward_kinematics(const UnityRig& rig, const UnityPose& pose, std::array<Vec3, kHumanoidBones.size()>& out_positions,
                              std::array<Quat, kHumanoidBones.size()>& out_rotations) {
  for (size_t b = 0; b < kHumanoidBones.size(); ++b) {
    const int p = rig.parent[b];
    if (p < 0) {
      out_positions[b] = pose.local_positions[b];
      out_rotations[b] = pose.local_rotations[b];
    } else {
      const auto pp = static_cast<size_t>(p);
      out_positions[b] = out_positions[pp] + out_rotations[pp] * pose.local_positions[b];
      out_rotations[b] = (out_rotations[pp] * pose.local_rotations[b]).normalized();
    }
  }
}

}  // namespace bodyd
