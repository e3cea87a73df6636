// The SolarXR bone convention (docs/protocol-solarxr.md, "Bones") on its defining pose: bodyd's
// reference T-pose turned to face -Z. Hand-derived expectations: spine and leg bones are the
// identity (tails straight down), the left arm's bones take -Y to -X and the right arm's to +X,
// every bone's tail is head + rotation_g * (0, -length, 0), and a turn of the whole body turns
// every bone by the same rotation (K is a constant of the joint).
#include "bodyd/io/solarxr/solarxr.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/humanoid.h"
#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>

namespace bodyd {
namespace {

namespace sx = daemon::solarxr;

struct TposeFixture {
  Skeleton skeleton;
  GlobalPose turned;  // the T-pose facing -Z
  sx::BoneMap map;
  TposeFixture() {
    skeleton = read_bvh(test::fixtures() / "walk_60.bvh").skeleton;
    RestPose rest;
    std::string error;
    EXPECT_TRUE(make_rest_pose(skeleton, rest, error)) << error;
    const Quat turn(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));
    turned = rest.global;
    for (auto& p : turned.positions) p = turn * p;
    for (auto& q : turned.rotations) q = turn * q;
    EXPECT_TRUE(map.build(skeleton, error)) << error;
  }
};

const sx::Bone& bone(const std::vector<sx::Bone>& bones, std::uint8_t part) {
  for (const auto& b : bones)
    if (b.body_part == part) return b;
  static const sx::Bone none;
  ADD_FAILURE() << "no bone " << int(part);
  return none;
}

TEST(SolarxrBones, TposeFacingMinusZ) {
  TposeFixture f;
  std::vector<sx::Bone> bones;
  f.map.bones(f.turned, bones);
  ASSERT_EQ(bones.size(), sx::kBoneDefs.size());
  for (std::uint8_t p : {sx::part::kHead, sx::part::kNeck, sx::part::kUpperChest, sx::part::kChest, sx::part::kWaist,
                         sx::part::kLeftUpperLeg, sx::part::kRightUpperLeg, sx::part::kLeftLowerLeg, sx::part::kRightLowerLeg}) {
    const Vec3 tail_dir = bone(bones, p).rotation_g * Vec3(0, -1, 0);
    // Within 5 degrees: the skeleton's own offsets are not exactly vertical (the chest's tilts 2.6 degrees).
    EXPECT_LT(tail_dir.y(), -std::cos(5.0 * M_PI / 180.0)) << "part " << int(p) << " should hang straight down";
  }
  for (std::uint8_t p : {sx::part::kLeftUpperArm, sx::part::kLeftLowerArm})
    EXPECT_LT((bone(bones, p).rotation_g * Vec3(0, -1, 0)).x(), -std::cos(5.0 * M_PI / 180.0)) << int(p);
  for (std::uint8_t p : {sx::part::kRightUpperArm, sx::part::kRightLowerArm})
    EXPECT_GT((bone(bones, p).rotation_g * Vec3(0, -1, 0)).x(), std::cos(5.0 * M_PI / 180.0)) << int(p);
  // Feet point forward (-Z) and down.
  const Vec3 foot = bone(bones, sx::part::kLeftFoot).rotation_g * Vec3(0, -1, 0);
  EXPECT_LT(foot.z(), -0.5);
  EXPECT_LT(foot.y(), 0.0);
}

TEST(SolarxrBones, TailsAreTheChildJointsAndATurnTurnsEveryBone) {
  TposeFixture f;
  // A pose: the turned T-pose, then the whole body turned by 37 degrees about an oblique axis
  // and moved: every bone turns and moves with it (the re-centring is undone before, in the
  // daemon: OutputSpace::Runtime).
  const Quat r(Eigen::AngleAxisd(37.0 * M_PI / 180.0, Vec3(0.3, 1.0, -0.2).normalized()));
  const Vec3 t(0.4, -0.1, 2.0);
  GlobalPose moved = f.turned;
  for (auto& p : moved.positions) p = r * p + t;
  for (auto& q : moved.rotations) q = r * q;
  std::vector<sx::Bone> a, b;
  f.map.bones(f.turned, a);
  f.map.bones(moved, b);
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_LT((b[i].rotation_g.toRotationMatrix() - (r * a[i].rotation_g).toRotationMatrix()).norm(), 1e-9);
    EXPECT_LT((b[i].head_position_m - (r * a[i].head_position_m + t)).norm(), 1e-9);
    EXPECT_FLOAT_EQ(a[i].length_m, b[i].length_m);
  }
  const auto tail_to = [&](std::uint8_t part, const char* child) {
    const sx::Bone& x = bone(b, part);
    const Vec3 tail = x.head_position_m + x.rotation_g * Vec3(0, -x.length_m, 0);
    EXPECT_LT((tail - moved.positions[static_cast<std::size_t>(f.skeleton.find(child))]).norm(), 1e-6) << child;
  };
  tail_to(sx::part::kLeftUpperArm, "LowerArm_L");
  tail_to(sx::part::kRightLowerArm, "Hand_R");
  tail_to(sx::part::kLeftUpperLeg, "LowerLeg_L");
  tail_to(sx::part::kRightFoot, "Toes_R");
  tail_to(sx::part::kLeftShoulder, "UpperArm_L");
}

TEST(SolarxrBones, ASkeletonWithoutTheHumanoidJointsIsRefused) {
  Skeleton s;
  s.names = {"Hips"};
  s.parents = {-1};
  s.offsets = {Vec3::Zero()};
  s.end_sites = {std::nullopt};
  sx::BoneMap map;
  std::string error;
  EXPECT_FALSE(map.build(s, error));
  EXPECT_FALSE(error.empty());
  EXPECT_FALSE(map.ready());
}

}  // namespace
}  // namespace bodyd
