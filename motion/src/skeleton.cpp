#include "bodyd/motion/skeleton.h"

#include <fmt/format.h>

namespace bodyd {

int Skeleton::find(std::string_view name) const {
  for (int i = 0; i < size(); ++i)
    if (names[static_cast<size_t>(i)] == name) return i;
  return -1;
}

std::string Skeleton::validate() const {
  const size_t n = names.size();
  if (n == 0) return "skeleton has no joints";
  if (parents.size() != n || offsets.size() != n || end_sites.size() != n)
    return fmt::format("skeleton arrays disagree in size ({} names, {} parents, {} offsets, {} end sites)", n,
                       parents.size(), offsets.size(), end_sites.size());
  if (parents[0] != -1) return "joint 0 must be the root (parent -1)";
  for (size_t i = 1; i < n; ++i) {
    if (parents[i] < 0 || static_cast<size_t>(parents[i]) >= i)
      return fmt::format("joint {} ('{}') has parent {}, which does not come before it", i, names[i], parents[i]);
  }
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 1; j < n; ++j)
      if (names[i] == names[j]) return fmt::format("joint name '{}' appears twice", names[i]);
  return {};
}

void forward_kinematics(const Skeleton& skeleton, const Pose& pose, GlobalPose& out) {
  const size_t n = static_cast<size_t>(skeleton.size());
  if (out.positions.size() != n) out.positions.resize(n);
  if (out.rotations.size() != n) out.rotations.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const int p = skeleton.parents[i];
    if (p < 0) {
      out.rotations[i] = pose.local_rotations[i];
      out.positions[i] = pose.local_translations[i];
    } else {
      const auto pi = static_cast<size_t>(p);
      out.rotations[i] = (out.rotations[pi] * pose.local_rotations[i]).normalized();
      out.positions[i] = out.positions[pi] + out.rotations[pi] * pose.local_translations[i];
    }
  }
}

GlobalPose forward_kinematics(const Skeleton& skeleton, const Pose& pose) {
  GlobalPose out;
  forward_kinematics(skeleton, pose, out);
  return out;
}

Pose rest_pose(const Skeleton& skeleton) {
  Pose p;
  p.local_rotations.assign(static_cast<size_t>(skeleton.size()), Quat::Identity());
  p.local_translations = skeleton.offsets;
  return p;
}

}  // namespace bodyd
