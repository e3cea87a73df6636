// The Razer Hydra decoder against hand-built 52-byte reports (synthesised from the layout
// in docs/drivers.md; no hardware capture was available) and its encoder.
#include "bodyd/io/devices/hydra.h"

#include <gtest/gtest.h>

#include <vector>

namespace bodyd::drivers {
namespace {

using Bytes = std::array<std::uint8_t, kHydraReportSize>;

// Controller 0: position (100, 200, -300) mm, identity rotation (w = 32767), buttons 0x05,
// joystick (0.5, -0.5), trigger full. Controller 1: all zeros (not tracking).
Bytes example() {
  Bytes b{};
  b[7] = 0x2A;
  const std::uint8_t c0[] = {0x64, 0x00, 0xC8, 0x00, 0xD4, 0xFE,              // x y z mm
                             0xFF, 0x7F, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // w x y z
                             0x05,                                            // buttons
                             0x00, 0x40, 0x00, 0xC0,                          // joystick
                             0xFF};                                           // trigger
  std::copy(std::begin(c0), std::end(c0), b.begin() + 8);
  return b;
}

// The change of basis of docs/drivers.md written out as a matrix (not as the quaternion
// the decoder uses): Hydra (x, y, z) -> bodyd (x, -z, y).
Vec3 to_bodyd(const Vec3& v) { return Vec3(v.x(), -v.z(), v.y()); }

TEST(Hydra, DecodesAHandBuiltReport) {
  const Bytes b = example();
  HydraOptions options;
  options.base_position_m = Vec3(0.0, 0.8, 0.0);
  HydraReport r;
  ASSERT_EQ(decode_hydra_report(b.data(), b.size(), options, r), HydraError::None);
  EXPECT_EQ(r.sequence, 0x2A);
  const HydraController& c = r.controllers[0];
  ASSERT_TRUE(c.valid);
  // (100, 200, -300) mm in the Hydra frame is (0.1, 0.3, 0.2) m from the base in bodyd's.
  EXPECT_NEAR(c.position_m.x(), 0.1, 1e-12);
  EXPECT_NEAR(c.position_m.y(), 0.8 + 0.3, 1e-12);
  EXPECT_NEAR(c.position_m.z(), 0.2, 1e-12);
  // Identity in the Hydra frame: only the half turn about the controller's x axis remains.
  EXPECT_LT(c.rotation.angularDistance(Quat(0, 1, 0, 0)), 1e-4);
  EXPECT_EQ(c.buttons, 0x05);
  EXPECT_NEAR(c.joystick_x, 0.5, 1e-12);
  EXPECT_NEAR(c.joystick_y, -0.5, 1e-12);
  EXPECT_NEAR(c.trigger, 1.0, 1e-12);
  EXPECT_FALSE(r.controllers[1].valid);

  const TrackerSample left = hydra_sample(r, 0, options, 7);
  EXPECT_EQ(left.role, Role::LeftHand);
  EXPECT_EQ(left.t_ns, 7);
  EXPECT_TRUE(left.valid);
  const TrackerSample right = hydra_sample(r, 1, options, 7);
  EXPECT_EQ(right.role, Role::RightHand);
  EXPECT_FALSE(right.valid);
}

TEST(Hydra, RotationConversionMatchesTheBasisChangeOnVectors) {
  // For any raw rotation q and vector v: R_bodyd * Rx(pi)^-1 * (M v) == M * (q v).
  const Quat flip_inv = Quat(0, 1, 0, 0).conjugate();
  const std::vector<Quat> raws{Quat(Eigen::AngleAxisd(0.7, Vec3(0.3, -0.5, 0.8).normalized())),
                               Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ())), Quat(0.0, 0.0, 1.0, 0.0)};
  for (const Quat& q : raws) {
    Bytes b = example();
    const double c[4] = {q.w(), q.x(), q.y(), q.z()};
    for (int i = 0; i < 4; ++i) {
      const auto v = static_cast<std::int16_t>(std::lround(c[i] * 32767.0));
      b[8 + 6 + 2 * i] = static_cast<std::uint8_t>(v & 0xFF);
      b[8 + 6 + 2 * i + 1] = static_cast<std::uint8_t>((v >> 8) & 0xFF);
    }
    HydraReport r;
    ASSERT_EQ(decode_hydra_report(b.data(), b.size(), HydraOptions{}, r), HydraError::None);
    for (const Vec3& v : {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.2, -0.4, 0.9)}) {
      const Vec3 lhs = r.controllers[0].rotation * (flip_inv * to_bodyd(v));
      const Vec3 rhs = to_bodyd(q * v);
      EXPECT_LT((lhs - rhs).norm(), 2e-4) << lhs.transpose() << " vs " << rhs.transpose();
    }
  }
}

TEST(Hydra, MalformedReports) {
  const Bytes b = example();
  HydraReport r;
  r.sequence = 99;
  for (std::size_t size : {0u, 51u, 53u, 22u})
    EXPECT_EQ(decode_hydra_report(b.data(), size, HydraOptions{}, r), HydraError::WrongSize) << size;
  EXPECT_EQ(decode_hydra_report(nullptr, 52, HydraOptions{}, r), HydraError::WrongSize);
  EXPECT_EQ(r.sequence, 99);
  EXPECT_EQ(describe_hydra_error(HydraError::WrongSize, 12), "Razer Hydra report of 12 bytes, expected 52");

  // A quaternion far from unit length (not tracking) makes that controller invalid, not the report.
  Bytes half = example();
  half[8 + 6] = 0x00;
  half[8 + 7] = 0x20;  // w = 0.25
  ASSERT_EQ(decode_hydra_report(half.data(), half.size(), HydraOptions{}, r), HydraError::None);
  EXPECT_FALSE(r.controllers[0].valid);
}

TEST(Hydra, EncodeDecodeRoundTrip) {
  HydraOptions options;
  options.controller_roles = {Role::RightHand, Role::LeftHand};
  HydraReport in;
  in.sequence = 200;
  in.controllers[0].valid = true;
  in.controllers[0].position_m = Vec3(-0.25, 1.1, 0.4);
  in.controllers[0].rotation = Quat(Eigen::AngleAxisd(2.0, Vec3(1, 2, 3).normalized()));
  in.controllers[0].buttons = 0x41;
  in.controllers[0].trigger = 0.5;
  in.controllers[1].valid = true;
  in.controllers[1].position_m = Vec3(0.3, 0.9, -0.1);
  in.controllers[1].rotation = Quat(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));
  const Bytes b = encode_hydra_report(in, options);
  HydraReport out;
  ASSERT_EQ(decode_hydra_report(b.data(), b.size(), options, out), HydraError::None);
  EXPECT_EQ(out.sequence, 200);
  for (int c = 0; c < 2; ++c) {
    ASSERT_TRUE(out.controllers[c].valid);
    EXPECT_LE((out.controllers[c].position_m - in.controllers[c].position_m).cwiseAbs().maxCoeff(), 0.5e-3 + 1e-12);
    EXPECT_LT(out.controllers[c].rotation.angularDistance(in.controllers[c].rotation), 2e-4);
  }
  EXPECT_EQ(out.controllers[0].buttons, 0x41);
  EXPECT_NEAR(out.controllers[0].trigger, 0.5, 1.0 / 255);
  EXPECT_EQ(hydra_sample(out, 0, options, 0).role, Role::RightHand);
}

TEST(Hydra, FeatureReportsHaveThePublishedBytes) {
  const auto motion = hydra_motion_mode_feature_report();
  ASSERT_EQ(motion.size(), 91u);
  for (std::size_t i = 0; i < motion.size(); ++i) {
    const std::uint8_t expected = i == 6 ? 0x01 : i == 8 ? 0x04 : i == 9 ? 0x03 : i == 89 ? 0x06 : 0x00;
    EXPECT_EQ(motion[i], expected) << "byte " << i;
  }
  const auto gamepad = hydra_gamepad_mode_feature_report();
  EXPECT_EQ(gamepad[9], 0x00);
  EXPECT_EQ(gamepad[89], 0x05);
}

}  // namespace
}  // namespace bodyd::drivers
