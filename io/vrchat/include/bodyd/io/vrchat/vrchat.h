// VRChat's OSC trackers (`bodyd --output vrchat:HOST:PORT`, docs/outputs.md "vrchat"): the
// slots, and the conversions from bodyd's space to what VRChat reads. Pure functions.
//
// Per pose, one OSC bundle (time tag "immediately") with, for each configured slot N in
// increasing order, /tracking/trackers/N/position (f x, y, z) and /tracking/trackers/N/rotation
// (f x, y, z), then /tracking/trackers/head/position and /tracking/trackers/head/rotation:
// the headset's pose as received, before the device offset (left out when the head sample is
// invalid). Reference: docs.vrchat.com, "OSC Trackers".
//
// Conversions (docs/outputs.md writes them out):
//   position: Unity axes, p_unity = (x, y, -z) of the joint's global position in bodyd space,
//             metres at the calibrated size.
//   rotation: the joint's global rotation R in bodyd space, mirrored into Unity's axes
//             (S R S, S = diag(1, 1, -1); quaternion (x, y, z, w) -> (-x, -y, z, w)), as the
//             Euler angles (degrees) Unity's Quaternion.Euler(x, y, z) takes: R = Ry(y) Rx(x) Rz(z),
//             i.e. applied Z first, then X, then Y.
#pragma once

#include "bodyd/io/vrchat/unity_euler.h"
#include "bodyd/motion/rotation.h"

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

namespace bodyd::daemon::vrchat {

inline constexpr std::string_view kDefaultHost = "127.0.0.1";
inline constexpr int kDefaultPort = 9000;  // VRChat's OSC input port

// VRChat's 8 tracker slots, numbered as SlimeVR numbers them.
struct TrackerSlot {
  int number;               // N of /tracking/trackers/N/...
  std::string_view name;    // its name in the `slots` option
  std::string_view joint;   // the skeleton joint it carries (docs/conventions.md names)
};
inline constexpr std::array<TrackerSlot, 8> kSlots{{
    {1, "hip", "Hips"},
    {2, "left_foot", "Foot_L"},
    {3, "right_foot", "Foot_R"},
    {4, "left_knee", "LowerLeg_L"},
    {5, "right_knee", "LowerLeg_R"},
    {6, "chest", "Chest"},
    {7, "left_elbow", "LowerArm_L"},
    {8, "right_elbow", "LowerArm_R"},
}};

// A set of slots: bit (N - 1) for slot N.
using SlotMask = std::uint8_t;
inline constexpr SlotMask kDefaultSlots = 0b0000'0111;  // hip and both feet (VRChat's advice)

// Parses the `slots` option: comma-separated names of kSlots or the groups hip, feet (2, 3),
// knees (4, 5), chest, elbows (7, 8). False with `error` set on an unknown or empty name.
[[nodiscard]] bool parse_slots(std::string_view text, SlotMask& out, std::string& error);
// "hip,left_foot,right_foot" (names of kSlots, in slot order).
[[nodiscard]] std::string slot_names(SlotMask mask);

// Unity's Euler angles of a rotation (the inverse of Quaternion.Euler): unity_euler_deg_from_quat,
// beside Quaternion.Euler itself in bodyd/io/vrchat/unity_euler.h.

// One tracker as VRChat reads it, from a pose in bodyd space.
struct TrackerPose {
  Vec3 position_unity = Vec3::Zero();   // metres
  Vec3 euler_deg_unity = Vec3::Zero();  // (x, y, z), Quaternion.Euler's arguments
};
[[nodiscard]] TrackerPose tracker_from_bodyd(const Vec3& position_m, const Quat& rotation);

}  // namespace bodyd::daemon::vrchat
