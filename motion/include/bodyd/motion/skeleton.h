// Skeleton (joint names, parents, rest offsets) and forward kinematics.
#pragma once

#include "bodyd/motion/rotation.h"

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd {

// Joints are stored so that a parent always comes before its children (index 0 is the root).
struct Skeleton {
  std::vector<std::string> names;
  std::vector<int> parents;   // -1 for the root
  std::vector<Vec3> offsets;  // rest offset from the parent, metres, in the parent's frame
  // BVH "End Site" offset per joint (metres), if the joint has one.
  std::vector<std::optional<Vec3>> end_sites;

  [[nodiscard]] int size() const { return static_cast<int>(names.size()); }
  // Index of a joint by name, or -1.
  [[nodiscard]] int find(std::string_view name) const;
  // Checks the invariants above; returns an empty string when valid, otherwise what is wrong.
  [[nodiscard]] std::string validate() const;
};

// A pose: per joint, the local rotation and the local translation (the rest offset
// for joints that do not translate; the BVH position channels where given).
struct Pose {
  std::vector<Quat> local_rotations;
  std::vector<Vec3> local_translations;
};

// Global (world) transforms of every joint.
struct GlobalPose {
  std::vector<Vec3> positions;  // metres
  std::vector<Quat> rotations;  // T_world_joint rotation
};

// Forward kinematics. `out` is resized only if its size differs (no allocation on reuse).
void forward_kinematics(const Skeleton& skeleton, const Pose& pose, GlobalPose& out);
[[nodiscard]] GlobalPose forward_kinematics(const Skeleton& skeleton, const Pose& pose);

// A pose with every joint at its rest offset and identity rotation.
[[nodiscard]] Pose rest_pose(const Skeleton& skeleton);

}  // namespace bodyd
