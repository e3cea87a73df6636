#include "bodyd/motion/tracker.h"

namespace bodyd {

std::string_view role_name(Role role) {
  switch (role) {
    case Role::Head: return "head";
    case Role::LeftHand: return "left_hand";
    case Role::RightHand: return "right_hand";
  }
  return "unknown";
}

std::optional<Role> role_from_name(std::string_view name) {
  for (Role r : kRoles)
    if (role_name(r) == name) return r;
  return std::nullopt;
}

std::string_view role_joint_name(Role role) {
  switch (role) {
    case Role::Head: return "Head";
    case Role::LeftHand: return "Hand_L";
    case Role::RightHand: return "Hand_R";
  }
  return "";
}

}  // namespace bodyd

namespace bodyd {

std::string_view pose_frame_name(PoseFrame frame) { return frame == PoseFrame::Device ? "device" : "joint"; }

std::optional<PoseFrame> pose_frame_from_name(std::string_view name) {
  if (name == "joint") return PoseFrame::Joint;
  if (name == "device" || name == "xr") return PoseFrame::Device;
  return std::nullopt;
}

}  // namespace bodyd
