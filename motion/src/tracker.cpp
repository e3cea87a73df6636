#include "bodyd/motion/tracker.h"

#include <algorithm>
#include <array>
#include <utility>

namespace bodyd {

namespace {

struct RoleNames {
  std::string_view name, joint;
};
constexpr std::array<RoleNames, kRoleCount> kNames{{{"head", "Head"},
                                                    {"left_hand", "Hand_L"},
                                                    {"right_hand", "Hand_R"},
                                                    {"hips", "Hips"},
                                                    {"chest", "Chest"},
                                                    {"left_foot", "Foot_L"},
                                                    {"right_foot", "Foot_R"},
                                                    {"left_knee", "LowerLeg_L"},
                                                    {"right_knee", "LowerLeg_R"},
                                                    {"left_elbow", "LowerArm_L"},
                                                    {"right_elbow", "LowerArm_R"}}};

}  // namespace

std::string_view role_name(Role role) {
  const auto i = static_cast<std::size_t>(role);
  return i < kNames.size() ? kNames[i].name : std::string_view("unknown");
}

std::optional<Role> role_from_name(std::string_view name) {
  for (Role r : kRoles)
    if (role_name(r) == name) return r;
  return std::nullopt;
}

std::string role_names_list() {
  std::string out;
  for (Role r : kRoles) out += (out.empty() ? "" : ", ") + std::string(role_name(r));
  return out;
}

bool TrackerSet::has(Role r) const { return std::find(roles.begin(), roles.end(), r) != roles.end(); }
bool TrackerSet::rotation_only_of(Role r) const {
  return std::find(rotation_only.begin(), rotation_only.end(), r) != rotation_only.end();
}

std::optional<TrackerSet> parse_tracker_set(std::string_view text, std::string& error) {
  static constexpr std::array<std::pair<std::string_view, std::array<Role, 2>>, 4> kGroups{{
      {"hands", {Role::LeftHand, Role::RightHand}},
      {"feet", {Role::LeftFoot, Role::RightFoot}},
      {"knees", {Role::LeftKnee, Role::RightKnee}},
      {"elbows", {Role::LeftElbow, Role::RightElbow}},
  }};
  std::array<int, kRoleCount> state{};  // 0 absent, 1 tracked, 2 rotation only
  std::size_t at = 0;
  while (at <= text.size()) {
    const std::size_t comma = text.find(',', at);
    std::string_view item = text.substr(at, comma == std::string_view::npos ? std::string_view::npos : comma - at);
    at = comma == std::string_view::npos ? text.size() + 1 : comma + 1;
    bool rot = false;
    if (item.size() > 4 && item.substr(item.size() - 4) == ":rot") {
      rot = true;
      item.remove_suffix(4);
    }
    std::vector<Role> named;
    if (const std::optional<Role> r = role_from_name(item)) named.push_back(*r);
    for (const auto& [group, pair] : kGroups)
      if (item == group) named.assign(pair.begin(), pair.end());
    if (named.empty()) {
      error = "tracker set \"" + std::string(text.substr(0, 200)) + "\": unknown tracker \"" +
              std::string(item.substr(0, 40)) + "\"; expected a comma list of " + role_names_list() +
              ", or the groups hands, feet, knees, elbows, each optionally followed by :rot (rotation only)";
      return std::nullopt;
    }
    for (Role r : named) {
      int& st = state[static_cast<std::size_t>(r)];
      if (st != 0) {
        error = "tracker set \"" + std::string(text.substr(0, 200)) + "\": " + std::string(role_name(r)) +
                " is named twice";
        return std::nullopt;
      }
      st = rot ? 2 : 1;
    }
  }
  if (state[static_cast<std::size_t>(Role::Head)] != 1) {
    error = "tracker set \"" + std::string(text.substr(0, 200)) +
            "\": the head (with its position) is required: the headset anchors the reconstruction";
    return std::nullopt;
  }
  TrackerSet set;
  for (Role r : kRoles) {
    const int st = state[static_cast<std::size_t>(r)];
    if (st != 0) set.roles.push_back(r);
    if (st == 2) set.rotation_only.push_back(r);
  }
  return set;
}

std::string tracker_set_text(const TrackerSet& set) {
  std::string out;
  for (Role r : set.roles)
    out += (out.empty() ? "" : ",") + std::string(role_name(r)) + (set.rotation_only_of(r) ? ":rot" : "");
  return out;
}

std::string_view role_joint_name(Role role) {
  const auto i = static_cast<std::size_t>(role);
  return i < kNames.size() ? kNames[i].joint : std::string_view();
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
