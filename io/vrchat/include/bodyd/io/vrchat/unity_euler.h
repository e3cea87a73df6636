// Unity's Euler angles (Quaternion.Euler, degrees) and their inverse, in one place: the vrchat:
// input reads VRChat's trackers and head as Euler angles (osc_decode.h's VrchatPose), the vrchat
// output writes them (vrchat.h). Both in Unity's axes (the mirror to bodyd's is unity_axes.h).
// Unity's order: R = Ry(y) Rx(x) Rz(z), i.e. z first, then x, then y (SlimeVR decodes them the
// same way, EulerOrder.YXZ). The functions keep their namespaces (the input's and the output's).
#pragma once

#include "bodyd/motion/rotation.h"

namespace bodyd::drivers {

// Unity's Quaternion.Euler(x, y, z) (degrees): q = Ry(y) * Rx(x) * Rz(z), in Unity's axes.
[[nodiscard]] Quat unity_euler_deg_to_quat(double x_deg, double y_deg, double z_deg);

}  // namespace bodyd::drivers

namespace bodyd::daemon::vrchat {

// Unity's Euler angles (degrees, (x, y, z)) of a rotation in Unity's axes: the inverse of
// Quaternion.Euler, R = Ry(y) Rx(x) Rz(z). x in [-90, 90], y and z in (-180, 180]. At gimbal
// lock (x = +-90 degrees, where only y - z or y + z is defined) z is 0.
[[nodiscard]] Vec3 unity_euler_deg_from_quat(const Quat& q_unity);

}  // namespace bodyd::daemon::vrchat
