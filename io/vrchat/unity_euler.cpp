// Unity's Euler angles, both ways (unity_euler.h): what VRChat sends (the vrchat: input) and what
// it reads (the vrchat output).
#include "bodyd/io/vrchat/unity_euler.h"

#include <Eigen/Dense>

#include <cmath>

namespace bodyd::drivers {

Quat unity_euler_deg_to_quat(double x_deg, double y_deg, double z_deg) {
  // Order "YXZ": R = Ry(y) * Rx(x) * Rz(z) (rotation.h applies the last axis first).
  static const EulerOrder kUnity = [] {
    EulerOrder o;
    (void)parse_euler_order("YXZ", o);
    return o;
  }();
  return quat_from_euler_deg(Vec3(y_deg, x_deg, z_deg), kUnity);
}

}  // namespace bodyd::drivers

namespace bodyd::daemon::vrchat {

Vec3 unity_euler_deg_from_quat(const Quat& q_unity) {
  const Eigen::Matrix3d r = q_unity.normalized().toRotationMatrix();
  // R = Ry(y) Rx(x) Rz(z) has   R(1,2) = -sin x,
  //   R(0,2) = sin y cos x,  R(2,2) = cos y cos x,  R(1,0) = cos x sin z,  R(1,1) = cos x cos z.
  const double cos_x = std::hypot(r(0, 2), r(2, 2));
  double x, y, z;
  if (cos_x > 1e-9) {
    x = std::atan2(-r(1, 2), cos_x);
    y = std::atan2(r(0, 2), r(2, 2));
    z = std::atan2(r(1, 0), r(1, 1));
  } else {
    // Gimbal lock: with z = 0, R = Ry(y) Rx(+-90) has R(0,0) = cos y, R(2,0) = -sin y.
    x = r(1, 2) < 0 ? M_PI / 2 : -M_PI / 2;
    y = std::atan2(-r(2, 0), r(0, 0));
    z = 0.0;
  }
  // atan2 gives -pi for (-0, negative): the range is (-180, 180], so half a turn is +180.
  const auto wrap = [](double a) { return a <= -M_PI ? a + 2.0 * M_PI : a; };
  constexpr double kDeg = 180.0 / M_PI;
  return Vec3(x * kDeg, wrap(y) * kDeg, wrap(z) * kDeg);
}

}  // namespace bodyd::daemon::vrchat
