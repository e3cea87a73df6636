#include "bodyd/inference/two_bone_ik.h"

#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <tuple>

using namespace bodyd;

namespace {

struct Arm {
  Motion motion;
  TwoBoneChain chain;
};

Arm left_arm() {
  Arm arm{read_bvh(test::fixtures() / "walk_60.bvh"), {}};
  const auto chain = find_two_bone_chain(arm.motion.skeleton, "UpperArm_L", "LowerArm_L", "Hand_L");
  EXPECT_TRUE(chain.has_value());
  if (chain) arm.chain = *chain;
  return arm;
}

Vec3 random_unit(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vec3 v(n(rng), n(rng), n(rng));
  return v.normalized();
}

bool descends_from(const Skeleton& s, int j, int ancestor) {
  for (; j >= 0; j = s.parents[static_cast<size_t>(j)])
    if (j == ancestor) return true;
  return false;
}

// The bend axis (upper bone x forearm) in the upper joint's frame.
Vec3 hinge_axis(const Pose& pose, const TwoBoneChain& c) {
  const Vec3 bone = pose.local_translations[static_cast<size_t>(c.lower)].normalized();
  const Vec3 forearm =
      (pose.local_rotations[static_cast<size_t>(c.lower)] * pose.local_translations[static_cast<size_t>(c.end)])
          .normalized();
  return bone.cross(forearm).normalized();
}

}  // namespace

TEST(TwoBoneIk, FindsChainsOnlyInParentOrder) {
  const Motion m = read_bvh(test::fixtures() / "bow_30.bvh");
  EXPECT_TRUE(find_two_bone_chain(m.skeleton, "UpperArm_R", "LowerArm_R", "Hand_R").has_value());
  EXPECT_FALSE(find_two_bone_chain(m.skeleton, "LowerArm_R", "UpperArm_R", "Hand_R").has_value());
  EXPECT_FALSE(find_two_bone_chain(m.skeleton, "UpperArm_R", "LowerArm_R", "Hand_L").has_value());
  EXPECT_FALSE(find_two_bone_chain(m.skeleton, "UpperArm_R", "LowerArm_R", "Paw_R").has_value());
}

TEST(TwoBoneIk, ReachableTargetsAreHitExactlyWithBonesAndRestOfBodyUnchanged) {
  const Arm arm = left_arm();
  const Skeleton& sk = arm.motion.skeleton;
  const TwoBoneChain& c = arm.chain;
  const auto u = static_cast<size_t>(c.upper), l = static_cast<size_t>(c.lower), e = static_cast<size_t>(c.end);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const bool hinge = trial % 2 == 1;
    Pose pose = arm.motion.frames[static_cast<size_t>(trial % arm.motion.frame_count())];
    GlobalPose g = forward_kinematics(sk, pose);
    const GlobalPose before = g;
    const Vec3 a = g.positions[u];
    const double lab = (g.positions[l] - a).norm(), lbc = (g.positions[e] - g.positions[l]).norm();
    const double lo = std::abs(lab - lbc), hi = lab + lbc;
    TwoBoneTarget target;
    target.position_m = a + (lo + (0.02 + 0.96 * unit(rng)) * (hi - lo)) * random_unit(rng);
    target.rotation = Quat(Eigen::AngleAxisd(M_PI * unit(rng), random_unit(rng)));
    if (trial % 3 == 0) target.pole_m = a + random_unit(rng);
    target.keep_hinge = hinge;
    const Vec3 axis_before = hinge_axis(pose, c);

    const TwoBoneResult r = solve_two_bone_ik(sk, c, target, pose, g);
    SCOPED_TRACE(::testing::Message() << "trial " << trial);
    EXPECT_TRUE(r.reachable);
    EXPECT_LT(r.error_m, 1e-9);
    EXPECT_LT((g.positions[e] - target.position_m).norm(), 1e-6);
    EXPECT_NEAR((g.positions[l] - g.positions[u]).norm(), lab, 1e-9);
    EXPECT_NEAR((g.positions[e] - g.positions[l]).norm(), lbc, 1e-9);
    EXPECT_LT(geodesic_angle(g.rotations[e], *target.rotation), 1e-9);
    // The elbow lies in the plane of shoulder, target and pole, on the pole's side.
    const Vec3 pole = target.pole_m ? *target.pole_m : before.positions[l];
    const Vec3 d = (target.position_m - a).normalized();
    const Vec3 toward = (pole - a) - (pole - a).dot(d) * d;
    const Vec3 normal = d.cross(toward).normalized();
    EXPECT_NEAR((g.positions[l] - a).dot(normal), 0.0, 1e-9);
    EXPECT_GT((g.positions[l] - a).dot(toward), 0.0);
    // Nothing outside the chain moved; `global` is the forward kinematics of `pose`.
    const GlobalPose fk = forward_kinematics(sk, pose);
    for (int j = 0; j < sk.size(); ++j) {
      const auto jj = static_cast<size_t>(j);
      EXPECT_LT((fk.positions[jj] - g.positions[jj]).norm(), 1e-12);
      if (!descends_from(sk, j, c.upper)) {
        EXPECT_EQ(g.positions[jj], before.positions[jj]) << sk.names[jj];
        EXPECT_EQ(pose.local_rotations[jj].coeffs(), arm.motion.frames[static_cast<size_t>(trial % arm.motion.frame_count())]
                                                      .local_rotations[jj]
                                                      .coeffs());
      }
      EXPECT_EQ(pose.local_translations[jj],
                arm.motion.frames[static_cast<size_t>(trial % arm.motion.frame_count())].local_translations[jj]);
    }
    // A hinge keeps the elbow's bend axis fixed in the upper arm.
    if (hinge) {
      EXPECT_GT(hinge_axis(pose, c).dot(axis_before), 1.0 - 1e-9);
    }
  }
}

TEST(TwoBoneIk, UnreachableTargetsClampAlongTheDirection) {
  const Arm arm = left_arm();
  const Skeleton& sk = arm.motion.skeleton;
  const TwoBoneChain& c = arm.chain;
  const auto u = static_cast<size_t>(c.upper), l = static_cast<size_t>(c.lower), e = static_cast<size_t>(c.end);
  for (const bool hinge : {false, true}) {
    Pose pose = arm.motion.frames[3];
    GlobalPose g = forward_kinematics(sk, pose);
    const Vec3 a = g.positions[u];
    const double lab = (g.positions[l] - a).norm(), lbc = (g.positions[e] - g.positions[l]).norm();
    const Vec3 dir = Vec3(0.3, -0.2, 0.9).normalized();

    TwoBoneTarget far;
    far.position_m = a + 5.0 * dir;
    far.keep_hinge = hinge;
    TwoBoneResult r = solve_two_bone_ik(sk, c, far, pose, g);
    EXPECT_FALSE(r.reachable);
    EXPECT_NEAR(r.error_m, 5.0 - (lab + lbc), 1e-9);
    EXPECT_LT((g.positions[e] - (a + (lab + lbc) * dir)).norm(), 1e-9);
    EXPECT_LT((g.positions[l] - a).cross(dir).norm(), 1e-9);  // stretched: elbow on the line
    EXPECT_NEAR((g.positions[l] - a).norm(), lab, 1e-9);

    TwoBoneTarget near;
    near.position_m = a + 0.001 * dir;
    near.keep_hinge = hinge;
    r = solve_two_bone_ik(sk, c, near, pose, g);
    EXPECT_FALSE(r.reachable);
    // Folded back on itself (a rotation by ~180 degrees): a little less precise.
    EXPECT_LT((g.positions[e] - (a + std::abs(lab - lbc) * dir)).norm(), 1e-7);

    TwoBoneTarget on_shoulder;  // no direction at all: must stay finite
    on_shoulder.position_m = a;
    on_shoulder.keep_hinge = hinge;
    r = solve_two_bone_ik(sk, c, on_shoulder, pose, g);
    EXPECT_TRUE(std::isfinite(r.error_m));
    for (const Vec3& p : g.positions) EXPECT_TRUE(p.allFinite());
    EXPECT_NEAR((g.positions[l] - a).norm(), lab, 1e-9);
  }
}

// The soft reach (TwoBoneTarget::soft_zone_m): targets short of the zone are hit exactly; inside
// it the hand lands on the shoulder-to-target line at the reach of the exponential curve, and
// the elbow moves far less for a millimetre of target motion near a straight arm than the hard
// law of cosines makes it.
TEST(TwoBoneIk, SoftReachSlowsTheElbowNearAStraightArm) {
  const Arm arm = left_arm();
  const Skeleton& sk = arm.motion.skeleton;
  const TwoBoneChain& c = arm.chain;
  const auto u = static_cast<size_t>(c.upper), l = static_cast<size_t>(c.lower), e = static_cast<size_t>(c.end);
  const Pose start = arm.motion.frames[3];
  const GlobalPose g0 = forward_kinematics(sk, start);
  const Vec3 a = g0.positions[u];
  const double full = (g0.positions[l] - a).norm() + (g0.positions[e] - g0.positions[l]).norm();
  const Vec3 dir = Vec3(0.3, -0.9, 0.2).normalized();
  const double zone = 0.03;

  // Solves for a target at distance `dist` along dir; returns the elbow and hand.
  const auto solve = [&](double dist, double soft) {
    Pose pose = start;
    GlobalPose g = g0;
    TwoBoneTarget t;
    t.position_m = a + dist * dir;
    t.soft_zone_m = soft;
    const TwoBoneResult r = solve_two_bone_ik(sk, c, t, pose, g);
    return std::tuple{g.positions[l], g.positions[e], r};
  };

  // Before the zone: exact, as without it.
  const auto [elbow_in, hand_in, r_in] = solve(full - 2.0 * zone, zone);
  EXPECT_TRUE(r_in.reachable);
  EXPECT_LT((hand_in - (a + (full - 2.0 * zone) * dir)).norm(), 1e-9);
  EXPECT_LT((elbow_in - std::get<0>(solve(full - 2.0 * zone, 0.0))).norm(), 1e-9);

  // In the zone and beyond full reach: on the line, at full - z exp(-(d - full + z) / z).
  for (const double dist : {full - 0.5 * zone, full, full + 0.05}) {
    const auto [elbow, hand, r] = solve(dist, zone);
    const double reach = full - zone * std::exp(-(dist - full + zone) / zone);
    EXPECT_FALSE(r.reachable);
    EXPECT_LT((hand - (a + reach * dir)).norm(), 1e-9) << dist;
    EXPECT_NEAR(r.error_m, dist - reach, 1e-9) << dist;
    EXPECT_NEAR((elbow - a).norm(), (g0.positions[l] - a).norm(), 1e-9);  // bones kept
  }
  // At full reach the hand falls short by z / e.
  EXPECT_NEAR(std::get<2>(solve(full, zone)).error_m, zone / std::exp(1.0), 1e-9);

  // The elbow's motion for 1 mm of target motion 3 mm short of full reach.
  const double d = full - 0.003;
  const double hard = (std::get<0>(solve(d + 0.001, 0.0)) - std::get<0>(solve(d, 0.0))).norm();
  const double soft = (std::get<0>(solve(d + 0.001, zone)) - std::get<0>(solve(d, zone))).norm();
  EXPECT_GT(hard, 0.004);  // the hard law of cosines: over 4 mm
  EXPECT_LT(soft, 0.4 * hard);

  // A zone wider than the arm's range of reach, or not finite, stays finite.
  for (const double bad : {10.0, std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN(),
                           -1.0}) {
    const auto [elbow, hand, r] = solve(full - 0.01, bad);
    EXPECT_TRUE(elbow.allFinite() && hand.allFinite() && std::isfinite(r.error_m)) << bad;
  }
}

TEST(TwoBoneIk, CurrentHandAsTargetLeavesThePoseAlone) {
  const Arm arm = left_arm();
  const Skeleton& sk = arm.motion.skeleton;
  for (const bool hinge : {false, true}) {
    Pose pose = arm.motion.frames[10];
    GlobalPose g = forward_kinematics(sk, pose);
    TwoBoneTarget t;
    t.position_m = g.positions[static_cast<size_t>(arm.chain.end)];
    t.keep_hinge = hinge;
    (void)solve_two_bone_ik(sk, arm.chain, t, pose, g);
    for (int j = 0; j < sk.size(); ++j)
      EXPECT_LT(geodesic_angle(pose.local_rotations[static_cast<size_t>(j)],
                               arm.motion.frames[10].local_rotations[static_cast<size_t>(j)]),
                1e-7)
          << sk.names[static_cast<size_t>(j)] << (hinge ? " (hinge)" : "");
  }
}
