// Tracker samples: the sparse input of bodyd.
#pragma once

#include "bodyd/motion/rotation.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd {

// The tracked roles, each the pose of one skeleton joint (see docs/conventions.md, "Tracker
// roles"): the headset and the two controllers (the XR roles every user has), then the body
// trackers some users add (issue 44).
enum class Role : std::uint8_t {
  Head = 0,
  LeftHand = 1,
  RightHand = 2,
  Hips = 3,
  Chest = 4,
  LeftFoot = 5,
  RightFoot = 6,
  LeftKnee = 7,
  RightKnee = 8,
  LeftElbow = 9,
  RightElbow = 10,
};
inline constexpr int kRoleCount = 11;
inline constexpr std::array<Role, kRoleCount> kRoles{Role::Head,     Role::LeftHand,  Role::RightHand, Role::Hips,
                                                     Role::Chest,    Role::LeftFoot,  Role::RightFoot, Role::LeftKnee,
                                                     Role::RightKnee, Role::LeftElbow, Role::RightElbow};
// The headset and the controllers: the roles of the default tracker set, whose devices the
// calibration pose and the default mounting know.
inline constexpr int kXrRoleCount = 3;
inline constexpr std::array<Role, kXrRoleCount> kXrRoles{Role::Head, Role::LeftHand, Role::RightHand};
[[nodiscard]] constexpr bool is_xr_role(Role role) { return static_cast<int>(role) < kXrRoleCount; }

// "head", "left_hand", "right_hand", "hips", "chest", "left_foot", "right_foot", "left_knee",
// "right_knee", "left_elbow", "right_elbow".
[[nodiscard]] std::string_view role_name(Role role);
[[nodiscard]] std::optional<Role> role_from_name(std::string_view name);
// The names joined with ", " (for messages listing what is accepted).
[[nodiscard]] std::string role_names_list();
// Skeleton joint tracked by a role: "Head", "Hand_L", "Hand_R", "Hips", "Chest", "Foot_L",
// "Foot_R", "LowerLeg_L" (the knee), "LowerLeg_R", "LowerArm_L" (the elbow), "LowerArm_R".
[[nodiscard]] std::string_view role_joint_name(Role role);

// A set of tracked roles (`bodyd-sim --trackers`, `bodyd-eval --trackers`): a comma list of role
// names and groups (`hands`, `feet`, `knees`, `elbows`: both sides), each optionally followed by
// `:rot` (rotation only, an IMU tracker), e.g. "head,hands,hips:rot,feet:rot". The head is
// required (its headset anchors the reconstruction); a role named twice is an error.
struct TrackerSet {
  std::vector<Role> roles;          // in kRoles order
  std::vector<Role> rotation_only;  // of `roles`
  [[nodiscard]] bool has(Role r) const;
  [[nodiscard]] bool rotation_only_of(Role r) const;
};
// nullopt and `error` (what is wrong, what is accepted) when `text` is not a set.
[[nodiscard]] std::optional<TrackerSet> parse_tracker_set(std::string_view text, std::string& error);
// The set as parse_tracker_set reads it, groups written out ("head,left_hand,right_hand,hips:rot").
[[nodiscard]] std::string tracker_set_text(const TrackerSet& set);

// What a sample's pose is the pose of (docs/conventions.md "Tracker roles", "Device frames"):
// - Joint: the skeleton joint itself (Head, Hand_L, Hand_R), as motion capture, simulated
//   joints and every log without a "frames" header line give it;
// - Device: the device in the common XR convention (right-handed, +Y up; the headset at the
//   point between the eyes looking along its -Z; a controller at its OpenXR grip pose). The
//   daemon and the evaluation map it to the joint through the role's mounting T_device_joint
//   (inference/mounting.h) before reconstruction.
enum class PoseFrame : std::uint8_t { Joint = 0, Device = 1 };

// "joint", "device".
[[nodiscard]] std::string_view pose_frame_name(PoseFrame frame);
// Accepts "joint" and "device" (and "xr", a synonym of "device"); nullopt otherwise.
[[nodiscard]] std::optional<PoseFrame> pose_frame_from_name(std::string_view name);

// One tracker sample. An invalid sample (tracking lost) carries no pose.
struct TrackerSample {
  std::int64_t t_ns = 0;  // host monotonic time (live) or the log's time base (replay)
  Role role = Role::Head;
  bool valid = false;
  Vec3 position_m = Vec3::Zero();           // world, metres
  Quat rotation = Quat::Identity();         // T_world_joint (or T_world_device) rotation, unit length
  PoseFrame frame = PoseFrame::Joint;       // what the pose is of (above)
  // A valid sample without a position (an IMU tracker, a headset tracked by rotation only):
  // only its rotation is observed (position_m is not used). Last, so that brace initialisers of
  // the fields above keep their meaning.
  bool has_position = true;
};

}  // namespace bodyd
