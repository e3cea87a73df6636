#include "bodyd/motion/rotation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace bodyd;

namespace {
Quat random_quat(std::mt19937& rng) {
  std::normal_distribution<double> n(0, 1);
  Quat q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized();
}
double angle_between(const Quat& a, const Quat& b) { return geodesic_angle(a, b); }
const char* kOrders[] = {"XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"};
}  // namespace

TEST(Rotation, AxisAngleRoundTrip) {
  std::mt19937 rng(1);
  for (int i = 0; i < 1000; ++i) {
    Quat q = random_quat(rng);
    Quat back = quat_from_axis_angle(axis_angle_from_quat(q));
    EXPECT_LT(angle_between(q, back), 1e-9);
  }
}

TEST(Rotation, AxisAngleHardCases) {
  // Angles at and near pi (w near 0), tiny angles, zero.
  for (double angle : {M_PI, M_PI - 1e-9, M_PI - 1e-6, 1e-12, 1e-8, 1e-5, 0.0}) {
    Vec3 axis = Vec3(0.3, -0.5, 0.8).normalized();
    Vec3 aa = axis * angle;
    Quat q = quat_from_axis_angle(aa);
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    Vec3 back = axis_angle_from_quat(q);
    EXPECT_NEAR((back - aa).norm(), 0.0, 1e-9) << "angle " << angle;
  }
  // A quaternion with w < 0 is the same rotation: the result has angle <= pi.
  Quat q(-0.1, 0.7, 0.7, 0.1);
  q.normalize();
  EXPECT_LE(axis_angle_from_quat(q).norm(), M_PI + 1e-12);
  EXPECT_LT(angle_between(quat_from_axis_angle(axis_angle_from_quat(q)), q), 1e-9);
  // Known value: 90 degrees about Y maps +Z to +X.
  Vec3 v = quat_from_axis_angle(Vec3(0, M_PI / 2, 0)) * Vec3::UnitZ();
  EXPECT_NEAR((v - Vec3::UnitX()).norm(), 0, 1e-12);
}

TEST(Rotation, EulerRoundTripAllOrders) {
  std::mt19937 rng(2);
  for (const char* name : kOrders) {
    EulerOrder order;
    ASSERT_TRUE(parse_euler_order(name, order));
    for (int i = 0; i < 500; ++i) {
      Quat q = random_quat(rng);
      Vec3 e = euler_deg_from_quat(q, order);
      EXPECT_LE(std::abs(e[1]), 90.0 + 1e-9);
      EXPECT_LT(angle_between(quat_from_euler_deg(e, order), q), 1e-9) << name;
    }
    // Gimbal lock: middle angle at +/-90.
    for (double mid : {90.0, -90.0}) {
      Quat q = quat_from_euler_deg(Vec3(30, mid, -20), order);
      Vec3 e = euler_deg_from_quat(q, order);
      EXPECT_LT(angle_between(quat_from_euler_deg(e, order), q), 1e-6) << name << " gimbal " << mid;
    }
  }
}

TEST(Rotation, EulerMatchesMatrixProduct) {
  // ZXY: R = Rz(a) Rx(b) Ry(c), checked against an independent matrix product.
  EulerOrder order;
  ASSERT_TRUE(parse_euler_order("ZXY", order));
  const double a = 0.3, b = -0.7, c = 1.1;
  auto Rx = [](double t) { Mat3 m; m << 1, 0, 0, 0, std::cos(t), -std::sin(t), 0, std::sin(t), std::cos(t); return m; };
  auto Ry = [](double t) { Mat3 m; m << std::cos(t), 0, std::sin(t), 0, 1, 0, -std::sin(t), 0, std::cos(t); return m; };
  auto Rz = [](double t) { Mat3 m; m << std::cos(t), -std::sin(t), 0, std::sin(t), std::cos(t), 0, 0, 0, 1; return m; };
  Mat3 expected = Rz(a) * Rx(b) * Ry(c);
  Quat q = quat_from_euler_deg(Vec3(a, b, c) * 180.0 / M_PI, order);
  EXPECT_LT((q.toRotationMatrix() - expected).norm(), 1e-12);
}

TEST(Rotation, ParseEulerOrderRejectsBadOrders) {
  EulerOrder o;
  EXPECT_FALSE(parse_euler_order("XXY", o));
  EXPECT_FALSE(parse_euler_order("XY", o));
  EXPECT_FALSE(parse_euler_order("ABC", o));
  EXPECT_TRUE(parse_euler_order("zxy", o));
}

TEST(Rotation, SixDRoundTripAndProjection) {
  std::mt19937 rng(3);
  for (int i = 0; i < 1000; ++i) {
    Quat q = random_quat(rng);
    EXPECT_LT(angle_between(quat_from_rot6d(rot6d_from_quat(q)), q), 1e-9);
  }
  // A perturbed, unnormalised 6D vector maps to a nearby rotation.
  Quat q = random_quat(rng);
  Vec6 r = rot6d_from_quat(q) * 3.0;
  r[1] += 0.01;
  EXPECT_LT(angle_between(quat_from_rot6d(r), q), 0.01);
  // Degenerate input (parallel columns) still gives a valid rotation.
  Vec6 bad;
  bad << 1, 0, 0, 2, 0, 0;
  EXPECT_NEAR(quat_from_rot6d(bad).norm(), 1.0, 1e-12);
}

TEST(Rotation, SlerpTakesShortestPathAndHitsEnds) {
  Quat a = quat_from_axis_angle(Vec3(0, 0.2, 0));
  Quat b = quat_from_axis_angle(Vec3(0, 0.6, 0));
  Quat b_neg(-b.w(), -b.x(), -b.y(), -b.z());
  EXPECT_LT(angle_between(slerp(a, b_neg, 0.5), quat_from_axis_angle(Vec3(0, 0.4, 0))), 1e-12);
  EXPECT_LT(angle_between(slerp(a, b, 0.0), a), 1e-12);
  EXPECT_LT(angle_between(slerp(a, b, 1.0), b), 1e-12);
}

TEST(Rotation, ThousandCompositionsDoNotDrift) {
  // 1000 compositions of a 0.36 degree step about one axis make exactly one full turn plus.
  Quat step = quat_from_axis_angle(Vec3(1, 2, 3).normalized() * (2 * M_PI / 1000.0));
  Quat q = Quat::Identity();
  for (int i = 0; i < 1000; ++i) q = (q * step).normalized();
  EXPECT_NEAR(q.norm(), 1.0, 1e-14);
  EXPECT_LT(geodesic_angle(q, Quat::Identity()), 1e-9);
  // Random rotation and its inverse, composed 1000 times, stays at identity.
  std::mt19937 rng(4);
  Quat r = random_quat(rng), acc = Quat::Identity();
  for (int i = 0; i < 1000; ++i) acc = (acc * r * r.conjugate()).normalized();
  EXPECT_LT(geodesic_angle(acc, Quat::Identity()), 1e-10);
}

TEST(Rotation, YawOf) {
  EXPECT_NEAR(yaw_of(quat_from_yaw(0.7), Vec3::UnitZ()), 0.7, 1e-12);
  EXPECT_NEAR(yaw_of(quat_from_yaw(-2.5), Vec3::UnitZ()), -2.5, 1e-12);
}
