// The motion representation of the model (docs/model.md): per-frame feature vectors in
// a canonical frame per window. One implementation, used by the runtime, the dataset
// export (training) and the evaluation.
//
// Per frame (kDim = 191 floats): for each of the 21 body joints (skeleton joints 1..21,
// every joint but joint_Root) its global position (3, metres) and global rotation as 6D
// (6), both expressed in the window's canonical frame; then the foot contacts of Toes_L
// and Toes_R (0 or 1). The canonical frame is the newest frame's head heading (yaw about
// +Y) and horizontal head position; heights stay absolute (the floor is y = 0).
#pragma once

#include "bodyd/motion/skeleton.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <span>
#include <string>
#include <string_view>

namespace bodyd::features {

// Bumped whenever the layout or meaning of a feature changes; stored in model files.
inline constexpr int kVersion = 1;

// The skeleton the features are defined on: joint names in index order (BVH order of the data).
inline constexpr std::array<std::string_view, 22> kJointNames{
    "joint_Root", "Hips",       "Spine",      "Chest",   "Neck",       "Head",       "Shoulder_L", "UpperArm_L",
    "LowerArm_L", "Hand_L",     "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R",  "UpperLeg_L", "LowerLeg_L",
    "Foot_L",     "Toes_L",     "UpperLeg_R", "LowerLeg_R", "Foot_R",     "Toes_R"};
inline constexpr int kHips = 1, kHead = 5, kHandL = 9, kHandR = 13, kToesL = 17, kToesR = 21;

// Model joints are the skeleton's joints 1..21 (every joint but joint_Root, index 0).
inline constexpr int kBodyJoints = 21;
inline constexpr int kPerJoint = 9;  // global position (3, metres) + global rotation 6D (6)
inline constexpr int kContactOffset = kBodyJoints * kPerJoint;  // 189: Toes_L, Toes_R contact (0/1)
inline constexpr int kDim = kContactOffset + 2;                 // 191

// Foot contact label: the toe is below this height and moves slower than this horizontally.
inline constexpr double kContactHeightM = 0.06;
inline constexpr double kContactSpeedMS = 0.20;

using Frame = std::span<float, kDim>;
using ConstFrame = std::span<const float, kDim>;

// Feature offset of body joint `skeleton_joint` (skeleton index, 1..21).
[[nodiscard]] constexpr int joint_offset(int skeleton_joint) { return (skeleton_joint - 1) * kPerJoint; }
// The skeleton joint a tracker role observes.
[[nodiscard]] constexpr int tracker_joint(Role role) {
  // kJointNames' indices of role_joint_name(role).
  constexpr std::array<int, kRoleCount> kJoint{kHead, kHandL, kHandR, kHips, 3, 16, 20, 15, 19, 8, 12};
  return kJoint[static_cast<std::size_t>(role)];
}

// Empty when `skeleton` has exactly the joints of kJointNames in that order with valid parents;
// otherwise what differs.
[[nodiscard]] std::string check_skeleton(const Skeleton& skeleton);

// The canonical frame of a window: T_canon_world = (rotation by -yaw about +Y) * (translation by -origin).
struct Canonical {
  double yaw_rad = 0.0;
  Vec3 origin_m = Vec3::Zero();  // (x, 0, z) of the head
  Quat R_world_canon = Quat::Identity();
  Quat R_canon_world = Quat::Identity();
};

// Heading of a head rotation: the twist about +Y of its rotation away from the upright reference
// orientation (facing +Z); robust to looking down or up (see docs/model.md).
[[nodiscard]] double head_yaw(const Quat& R_world_head);
[[nodiscard]] Canonical canonical_from_head(const Vec3& head_position_m, const Quat& R_world_head);

// Writes one joint's position and rotation (world) into a frame's entries for that joint.
void encode_joint(int skeleton_joint, const Vec3& position_m, const Quat& rotation, const Canonical& c, Frame out);
// Encodes a whole frame from world-space global joint transforms (skeleton of kJointNames).
void encode_pose(const GlobalPose& global, const std::array<bool, 2>& contact, const Canonical& c, Frame out);
// One frame's joint entries before the canonical transform: for each body joint its world
// position and the first two columns of its world rotation. A window's past frames stay the same
// from one frame to the next while its canonical frame moves, so the online loop keeps these for
// every frame it emits and turns them into each new window's frame (encode_world_entries) instead
// of encoding the whole pose again: a rotation of three vectors per joint.
struct WorldEntries {
  std::array<Vec3, static_cast<size_t>(kBodyJoints) * 3> v;  // joint j (1..21): p, R.col(0), R.col(1)
};
void world_entries(const GlobalPose& global, WorldEntries& out);
// encode_pose of the pose whose world entries these are (equal to it up to rounding).
void encode_world_entries(const WorldEntries& world, const std::array<bool, 2>& contact, const Canonical& c, Frame out);
// Reads one joint's position and rotation (world) back.
void decode_joint(int skeleton_joint, ConstFrame in, const Canonical& c, Vec3& out_position_m, Quat& out_rotation);
// Decodes a frame into a local pose on `skeleton`: joint rotations from the 6D global rotations,
// the Hips translation from its position, every other joint at its rest offset. joint_Root is
// identity at the origin. `out_pose` must already have skeleton.size() entries (no allocation).
void decode_pose(const Skeleton& skeleton, ConstFrame in, const Canonical& c, Pose& out_pose,
                 std::array<bool, 2>& out_contact);

// Contact labels of the feet from two consecutive frames `dt_s` apart.
[[nodiscard]] std::array<bool, 2> contact_labels(const GlobalPose& previous, const GlobalPose& current, double dt_s);

// Indices (within a frame) of the entries a tracker role observes (9 each).
[[nodiscard]] std::array<int, kPerJoint> tracker_entries(Role role);

}  // namespace bodyd::features
