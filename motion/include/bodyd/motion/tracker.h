// Tracker samples: the sparse input of bodyd.
#pragma once

#include "bodyd/motion/rotation.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

namespace bodyd {

// The three tracked roles, each the pose of one skeleton joint (see docs/conventions.md).
enum class Role : std::uint8_t { Head = 0, LeftHand = 1, RightHand = 2 };
inline constexpr int kRoleCount = 3;
inline constexpr std::array<Role, kRoleCount> kRoles{Role::Head, Role::LeftHand, Role::RightHand};

// "head", "left_hand", "right_hand".
[[nodiscard]] std::string_view role_name(Role role);
[[nodiscard]] std::optional<Role> role_from_name(std::string_view name);
// Skeleton joint tracked by a role: "Head", "Hand_L", "Hand_R".
[[nodiscard]] std::string_view role_joint_name(Role role);

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
};

}  // namespace bodyd
