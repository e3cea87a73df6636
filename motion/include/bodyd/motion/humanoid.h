// The skeleton's reference T-pose ("rest pose") and the retargeting of bodyd's poses to
// Unity's humanoid convention (HumanBodyBones, left-handed axes, every bone's rotation the
// identity in the T-pose), as the VMC protocol's receivers expect them (docs/vmc.md).
//
// Why: a joint's local frame in bodyd's skeleton (the bundled motion data's) is its BVH frame,
// whose axes differ from joint to joint (the spine's X points up, the left arm's X points
// left, the right leg's X points up along the bone that hangs down its -X...), and its rest
// offsets with identity rotations give no meaningful pose. The reference T-pose below names,
// for every joint, where its local axes point when the body stands in a T-pose, so a
// retargeter can express any pose as rotations relative to that T-pose.
//
// The T-pose (docs/protocol.md, "Rest pose"): standing on the floor (y = 0) at the origin,
// facing +Z (bodyd's forward: the heading yaw 0 looks along +Z), left along +X, up +Y; spine,
// neck and head vertical; arms horizontal along +-X with the palms down (elbow hinge
// vertical); legs vertical; each foot bone pointing forward and kRestFootPitchDeg below
// horizontal, the toes kRestToesPitchDeg below (the feet of a person standing, so an avatar's
// feet are flat when the user's are); the lower Toes joint kRestToesHeightM above the floor.
#pragma once

#include "bodyd/motion/skeleton.h"
#include "bodyd/motion/unity_axes.h"  // unity_from_bodyd: bodyd's axes to Unity's

#include <array>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd {

// Measured on the standing reference frame of the bundled data (frame 5 of
// dataset-1_call_normal_002: feet 38-41 degrees, toes 22-24 degrees below horizontal, the lower
// Toes joint 4.5 cm above the floor).
inline constexpr double kRestFootPitchDeg = 40.0;
inline constexpr double kRestToesPitchDeg = 22.0;
inline constexpr double kRestToesHeightM = 0.045;

struct RestPose {
  // Per joint, the rest offset from the parent in the parent's frame (metres): the skeleton's
  // offsets, except the Hips' (a clip's world position in the BVH file), which becomes
  // (0, h, 0) in joint_Root's frame so that the T-pose stands on the floor.
  std::vector<Vec3> offsets;
  // Per joint, the rest rotation relative to the parent (T_parent_joint at rest).
  std::vector<Quat> rotations;
  // Forward kinematics of the above: the T-pose in world coordinates.
  GlobalPose global;
};

// The reference T-pose of `skeleton` (any scale). False, with `out_error` naming the joint, if
// the skeleton lacks a joint of the bundled data's skeleton or a joint's parent differs.
[[nodiscard]] bool make_rest_pose(const Skeleton& skeleton, RestPose& out, std::string& out_error);

// ---- Unity humanoid ------------------------------------------------------------------------

struct HumanoidBone {
  std::string_view unity;  // Unity's HumanBodyBones name, as the VMC protocol sends it
  std::string_view bodyd;  // the joint of bodyd's skeleton
};
// The 21 bones, parents before children. The Unity parent of each is the bone of its bodyd
// parent joint (Hips' parent is the avatar root). joint_Root has no Unity bone.
inline constexpr std::array<HumanoidBone, 21> kHumanoidBones{{
    {"Hips", "Hips"},
    {"Spine", "Spine"},
    {"Chest", "Chest"},
    {"Neck", "Neck"},
    {"Head", "Head"},
    {"LeftShoulder", "Shoulder_L"},
    {"LeftUpperArm", "UpperArm_L"},
    {"LeftLowerArm", "LowerArm_L"},
    {"LeftHand", "Hand_L"},
    {"RightShoulder", "Shoulder_R"},
    {"RightUpperArm", "UpperArm_R"},
    {"RightLowerArm", "LowerArm_R"},
    {"RightHand", "Hand_R"},
    {"LeftUpperLeg", "UpperLeg_L"},
    {"LeftLowerLeg", "LowerLeg_L"},
    {"LeftFoot", "Foot_L"},
    {"LeftToes", "Toes_L"},
    {"RightUpperLeg", "UpperLeg_R"},
    {"RightLowerLeg", "LowerLeg_R"},
    {"RightFoot", "Foot_R"},
    {"RightToes", "Toes_R"},
}};

// What the retargeting needs of a skeleton, computed once per skeleton (make_unity_rig).
struct UnityRig {
  std::array<int, kHumanoidBones.size()> joint{};   // bodyd joint index of each bone
  std::array<int, kHumanoidBones.size()> parent{};  // parent bone index; -1 for Hips
  // Unity local position of each bone in the T-pose (metres, Unity axes, the parent's frame,
  // which in the T-pose is the avatar's): the bone's offset from its parent. Hips: its T-pose
  // position above the root. Constant: bones do not stretch.
  std::array<Vec3, kHumanoidBones.size()> tpose_local_position{};
  // Inverse of each bone's joint global rotation in the T-pose turned to face Unity's forward
  // (bodyd -Z), bodyd axes.
  std::array<Quat, kHumanoidBones.size()> tpose_global_inverse{};
};

// False with `out_error` set as make_rest_pose.
[[nodiscard]] bool make_unity_rig(const Skeleton& skeleton, UnityRig& out, std::string& out_error);

// One pose in Unity's humanoid convention, as the VMC protocol's /VMC/Ext/Bone/Pos carries it.
struct UnityPose {
  // Per bone (kHumanoidBones order), Transform.localPosition (Unity axes, metres): the rig's
  // T-pose offset, except the Hips': its position relative to the avatar root, which stays at
  // the origin with identity rotation (bodyd's world origin and axes, converted).
  std::array<Vec3, kHumanoidBones.size()> local_positions{};
  // Per bone, Transform.localRotation (Unity axes): identity in the T-pose facing Unity's +Z.
  std::array<Quat, kHumanoidBones.size()> local_rotations{};
};

// Retargets a global pose (bodyd space, on the rig's skeleton) to Unity's humanoid. Pure, no
// allocation. For every bone b with bodyd joint j and parent bone p:
//   G_b = unity_from_bodyd(R_j * tpose_global_inverse_b)       (its global rotation, T-pose = I)
//   local_rotation_b = G_p^-1 * G_b  (G_p = I for Hips)
// so forward kinematics over the Unity hierarchy with local_positions and local_rotations
// gives back unity_from_bodyd(position_j) for every joint.
void retarget_to_unity(const UnityRig& rig, const GlobalPose& global, UnityPose& out);

// Forward kinematics over the Unity hierarchy (root at the origin, identity): global positions
// and rotations per bone, Unity axes. For tests and for receivers written from the doc.
void unity_forward_kinematics(const UnityRig& rig, const UnityPose& pose, std::array<Vec3, kHumanoidBones.size()>& out_positions,
                              std::array<Quat, kHumanoidBones.size()>& out_rotations);

}  // namespace bodyd
