// Rotation helpers shared by every part of bodyd.
//
// Conventions (docs/conventions.md): right-handed, +Y up, metres.
// Quaternions are Eigen::Quaterniond inside C++; files and the wire use (x, y, z, w).
// Every function returning a quaternion returns it unit length.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <string_view>

namespace bodyd {

using Vec3 = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;
using Mat3 = Eigen::Matrix3d;
using Vec6 = Eigen::Matrix<double, 6, 1>;

// Rotation by the vector's norm (radians) about its direction. Exact for tiny angles.
[[nodiscard]] Quat quat_from_axis_angle(const Vec3& axis_angle_rad);
// Inverse of quat_from_axis_angle, with the angle in [0, pi].
[[nodiscard]] Vec3 axis_angle_from_quat(const Quat& q);

// An Euler order names the axes of three intrinsic rotations, applied as
// R = R_a(angle0) * R_b(angle1) * R_c(angle2) for order "abc" (BVH's meaning of
// a channel list "Zrotation Xrotation Yrotation" is order "ZXY").
struct EulerOrder {
  std::array<int, 3> axes{2, 0, 1};  // 0 = X, 1 = Y, 2 = Z
};
// Parses "XYZ", "zxy", ...; Tait-Bryan orders only (three different axes). Returns false otherwise.
[[nodiscard]] bool parse_euler_order(std::string_view text, EulerOrder& out_order);

[[nodiscard]] Quat quat_from_euler_deg(const Vec3& angles_deg, const EulerOrder& order);
// Angles (degrees) with the middle one in [-90, 90]; at gimbal lock the last angle is 0.
[[nodiscard]] Vec3 euler_deg_from_quat(const Quat& q, const EulerOrder& order);

// 6D rotation representation (Zhou et al. 2019): the first two columns of the
// rotation matrix, stacked (column 0 then column 1).
[[nodiscard]] Vec6 rot6d_from_quat(const Quat& q);
// Gram-Schmidt back to a rotation; any input whose two columns are not parallel works.
[[nodiscard]] Quat quat_from_rot6d(const Vec6& r6);

// Shortest-path spherical interpolation, t in [0, 1].
[[nodiscard]] Quat slerp(const Quat& a, const Quat& b, double t);
// Angle between two rotations, radians in [0, pi].
[[nodiscard]] double geodesic_angle(const Quat& a, const Quat& b);

// Rotation about +Y (heading) by yaw radians.
[[nodiscard]] Quat quat_from_yaw(double yaw_rad);
// Heading of a rotation: yaw of the rotated `forward` vector projected on the floor (x, z),
// measured as atan2(f.x, f.z) so that yaw 0 looks along +Z.
[[nodiscard]] double yaw_of(const Quat& q, const Vec3& forward);

}  // namespace bodyd
