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
