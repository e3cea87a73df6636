#include "bodyd/motion/rotation.h"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace bodyd {

Quat quat_from_axis_angle(const Vec3& axis_angle_rad) {
  const double angle = axis_angle_rad.norm();
  const double half = 0.5 * angle;
  // sin(half)/angle, by its Taylor series for tiny angles (exact to double precision below 1e-4).
  const double k = angle < 1e-4 ? 0.5 - angle * angle / 48.0 : std::sin(half) / angle;
  Quat q(std::cos(half), k * axis_angle_rad.x(), k * axis_angle_rad.y(), k * axis_angle_rad.z());
  q.normalize();
  return q;
}

Vec3 axis_angle_from_quat(const Quat& q_in) {
  Quat q = q_in.normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // same rotation, angle in [0, pi]
  const double s = q.vec().norm();
  // atan2 is well conditioned both near 0 and near pi (where w -> 0).
  const double angle = 2.0 * std::atan2(s, q.w());
  if (s < 1e-12) return 2.0 * q.vec();  // tiny angle: sin(half) ~ half
  return q.vec() * (angle / s);
}

bool parse_euler_order(std::string_view text, EulerOrder& out_order) {
  if (text.size() != 3) return false;
  EulerOrder order;
  for (int i = 0; i < 3; ++i) {
    const char c = static_cast<char>(std::toupper(static_cast<unsigned char>(text[i])));
    if (c < 'X' || c > 'Z') return false;
    order.axes[i] = c - 'X';
  }
  if (order.axes[0] == order.axes[1] || order.axes[1] == order.axes[2] || order.axes[0] == order.axes[2])
    return false;
  out_order = order;
  return true;
}

Quat quat_from_euler_deg(const Vec3& angles_deg, const EulerOrder& order) {
  Quat q = Quat::Identity();
  for (int i = 0; i < 3; ++i) {
    const double rad = angles_deg[i] * M_PI / 180.0;
    q = q * Quat(Eigen::AngleAxisd(rad, Vec3::Unit(order.axes[i])));
  }
  return q.normalized();
}

Vec3 euler_deg_from_quat(const Quat& q, const EulerOrder& order) {
  // R = R_i(a) R_j(b) R_k(c). With s = +1 for cyclic orders (XYZ, YZX, ZXY) and -1 otherwise:
  // R(i,k) = s*sin(b), R(j,k) = -s*sin(a)cos(b), R(k,k) = cos(a)cos(b),
  // R(i,j) = -s*cos(b)sin(c), R(i,i) = cos(b)cos(c).
  const int i = order.axes[0], j = order.axes[1], k = order.axes[2];
  const double s = ((j - i + 3) % 3 == 1) ? 1.0 : -1.0;
  const Mat3 R = q.normalized().toRotationMatrix();
  const double sb = std::clamp(s * R(i, k), -1.0, 1.0);
  double a, b, c;
  b = std::asin(sb);
  if (std::abs(sb) < 1.0 - 1e-12) {
    a = std::atan2(-s * R(j, k), R(k, k));
    c = std::atan2(-s * R(i, j), R(i, i));
  } else {
    // Gimbal lock: only a +/- c is determined; put it all in a.
    c = 0.0;
    a = std::atan2(s * R(k, j), R(j, j));
  }
  return Vec3(a, b, c) * (180.0 / M_PI);
}

Vec6 rot6d_from_quat(const Quat& q) {
  const Mat3 R = q.normalized().toRotationMatrix();
  Vec6 out;
  out << R.col(0), R.col(1);
  return out;
}

Quat quat_from_rot6d(const Vec6& r6) {
  Vec3 a = r6.head<3>();
  Vec3 b = r6.tail<3>();
  const double na = a.norm();
  Vec3 x = na > 1e-12 ? Vec3(a / na) : Vec3::UnitX();
  Vec3 y = b - x.dot(b) * x;
  double ny = y.norm();
  if (ny < 1e-12) {
    // Degenerate input: pick any axis orthogonal to x.
    y = x.unitOrthogonal();
    ny = 1.0;
  }
  y /= ny;
  Mat3 R;
  R.col(0) = x;
  R.col(1) = y;
  R.col(2) = x.cross(y);
  return Quat(R).normalized();
}

Quat slerp(const Quat& a, const Quat& b, double t) {
  Quat bb = b;
  if (a.dot(b) < 0) bb.coeffs() = -b.coeffs();
  return a.slerp(t, bb).normalized();
}

double geodesic_angle(const Quat& a, const Quat& b) {
  // atan2 of the relative rotation keeps full precision near 0 (acos of a dot product loses half the digits).
  const Quat r = a.normalized().conjugate() * b.normalized();
  return 2.0 * std::atan2(r.vec().norm(), std::abs(r.w()));
}

Quat quat_from_yaw(double yaw_rad) { return Quat(Eigen::AngleAxisd(yaw_rad, Vec3::UnitY())); }

double yaw_of(const Quat& q, const Vec3& forward) {
  const Vec3 f = q * forward;
  return std::atan2(f.x(), f.z());
}

}  // namespace bodyd
