#include "bodyd/motion/skeleton.h"

#include <gtest/gtest.h>

using namespace bodyd;

namespace {
// root -> a -> b, each bone 1 m along x.
Skeleton chain() {
  Skeleton s;
  s.names = {"root", "a", "b"};
  s.parents = {-1, 0, 1};
  s.offsets = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 0, 0)};
  s.end_sites = {std::nullopt, std::nullopt, Vec3(0.5, 0, 0)};
  return s;
}
}  // namespace

TEST(Skeleton, ValidateAndFind) {
  Skeleton s = chain();
  EXPECT_EQ(s.validate(), "");
  EXPECT_EQ(s.find("b"), 2);
  EXPECT_EQ(s.find("nope"), -1);
  s.parents[1] = 2;
  EXPECT_NE(s.validate(), "");
  s = chain();
  s.names[2] = "a";
  EXPECT_NE(s.validate(), "");
}

TEST(Skeleton, ForwardKinematicsHandComputed) {
  Skeleton s = chain();
  Pose p = rest_pose(s);
  p.local_translations[0] = Vec3(0, 1, 0);
  // Root turns 90 degrees about Z: bone a points along +y. Joint a turns -90 about Z: bone b along +x again.
  p.local_rotations[0] = Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()));
  p.local_rotations[1] = Quat(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitZ()));
  GlobalPose g = forward_kinematics(s, p);
  EXPECT_NEAR((g.positions[0] - Vec3(0, 1, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((g.positions[1] - Vec3(0, 2, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((g.positions[2] - Vec3(1, 2, 0)).norm(), 0, 1e-12);
  EXPECT_LT(geodesic_angle(g.rotations[2], Quat::Identity()), 1e-12);
  // Reuse of the output does not change results.
  forward_kinematics(s, p, g);
  EXPECT_NEAR((g.positions[2] - Vec3(1, 2, 0)).norm(), 0, 1e-12);
}
