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

// One tracker sample. An invalid sample (tracking lost) carries no pose.
struct TrackerSample {
  std::int64_t t_ns = 0;  // host monotonic time (live) or the log's time base (replay)
  Role role = Role::Head;
  bool valid = false;
  Vec3 position_m = Vec3::Zero();           // world, metres
  Quat rotation = Quat::Identity();         // T_world_joint rotation, unit length
};

}  // namespace bodyd
