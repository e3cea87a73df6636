// Unity's axes, the one definition (docs/conventions.md): VRChat OSC, VMC and Unity avatars use
// Unity's left-handed frame (x right, y up, z forward); bodyd's is right-handed (x right, y up,
// the user facing -z at rest). The change of basis is the mirror S = diag(1, 1, -1):
// a position (x, y, z) -> (x, y, -z), a rotation R -> S R S, i.e. quaternion
// (x, y, z, w) -> (-x, -y, z, w). The mirror is its own inverse, so one function converts either
// way; bodyd_from_unity says which way a caller means.
#pragma once

#include "bodyd/motion/rotation.h"

namespace bodyd {

[[nodiscard]] inline Vec3 unity_from_bodyd(const Vec3& p) { return Vec3(p.x(), p.y(), -p.z()); }
[[nodiscard]] inline Quat unity_from_bodyd(const Quat& q) { return Quat(q.w(), -q.x(), -q.y(), q.z()); }
[[nodiscard]] inline Vec3 bodyd_from_unity(const Vec3& p_unity) { return unity_from_bodyd(p_unity); }
[[nodiscard]] inline Quat bodyd_from_unity(const Quat& q_unity) { return unity_from_bodyd(q_unity); }

}  // namespace bodyd
