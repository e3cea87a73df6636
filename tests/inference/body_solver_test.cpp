// The tracked joints exact (issue 10 item 3): the Head joint on the head tracker wherever the
// network put the neck, the hands on theirs even at full reach, without flips or added jitter.
#include "bodyd/inference/body_solver.h"
#include "bodyd/inference/two_bone_ik.h"

#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using namespace bodyd;

namespace {

const Motion& walk() {
  static const Motion m = read_bvh(test::fixtures() / "walk_60.bvh");
  return m;
}
const Skeleton& sk() { return walk().skeleton; }
int J(const char* name) { return sk().find(name); }
const Vec3& pos(const GlobalPose& g, const char* name) { return g.positions[static_cast<size_t>(J(name))]; }

double arm_length(int side) {
  const char* lower = side == 0 ? "LowerArm_L" : "LowerArm_R";
  const char* hand = side == 0 ? "Hand_L" : "Hand_R";
  return sk().offsets[static_cast<size_t>(J(lower))].norm() + sk().offsets[static_cast<size_t>(J(hand))].norm();
}

// The diffusion reconstructor's order: the body solver, then two-bone IK per tracked arm.
void solve_all(const TrackedTargets& t, Pose& pose, GlobalPose& g, const BodySolverOptions& o = {}) {
  const std::optional<UpperBody> body = find_upper_body(sk());
  ASSERT_TRUE(body);
  (void)solve_tracked_body(sk(), *body, o, t, pose, g);
  for (int s = 0; s < 2; ++s) {
    if (!t.hand_valid[static_cast<size_t>(s)]) continue;
    const auto chain = s == 0 ? find_two_bone_chain(sk(), "UpperArm_L", "LowerArm_L", "Hand_L")
                              : find_two_bone_chain(sk(), "UpperArm_R", "LowerArm_R", "Hand_R");
    TwoBoneTarget target;
    target.position_m = t.hand_m[static_cast<size_t>(s)];
    (void)solve_two_bone_ik(sk(), *chain, target, pose, g);
  }
}

}  // namespace

TEST(BodySolver, FindsTheUpperBodyAndRefusesABrokenChain) {
  const std::optional<UpperBody> b = find_upper_body(sk());
  ASSERT_TRUE(b);
  EXPECT_EQ(b->head, J("Head"));
  EXPECT_EQ(b->shoulder[1], J("Shoulder_R"));
  Skeleton broken = sk();
  broken.parents[static_cast<size_t>(J("Neck"))] = J("Spine");
  EXPECT_FALSE(find_upper_body(broken));
}

TEST(BodySolver, HeadFarFromThePredictedNeckLandsExactly) {
  // The network's pose is frame 20; the tracker says the head is 12 cm away (as far as the
  // default model's worst frames on the validation split) and turned.
  Pose pose = walk().frames[20];
  GlobalPose g = forward_kinematics(sk(), pose);
  const Pose before = pose;
  TrackedTargets t;
  t.head_valid = true;
  t.head_m = pos(g, "Head") + Vec3(0.07, -0.06, 0.08);
  t.head_body_m = t.head_m;
  t.head_rotation = (Quat(Eigen::AngleAxisd(0.4, Vec3(0.2, 1.0, 0.3).normalized())) *
                     g.rotations[static_cast<size_t>(J("Head"))]).normalized();
  const BodySolverResult r = solve_tracked_body(sk(), *find_upper_body(sk()), {}, t, pose, g);
  EXPECT_LT((pos(g, "Head") - t.head_m).norm(), 1e-6);
  EXPECT_LT(r.head_error_m, 1e-6);
  EXPECT_LT(geodesic_angle(g.rotations[static_cast<size_t>(J("Head"))], t.head_rotation), 1e-6);
  // g is forward kinematics of the returned pose.
  const GlobalPose fk = forward_kinematics(sk(), pose);
  for (size_t j = 0; j < fk.positions.size(); ++j) EXPECT_LT((fk.positions[j] - g.positions[j]).norm(), 1e-12);
  // Bones keep their lengths; the legs and arms below the clavicles keep their local rotations.
  for (int j = 0; j < sk().size(); ++j) {
    const auto u = static_cast<size_t>(j);
    if (j == J("Hips")) continue;
    EXPECT_EQ(pose.local_translations[u], before.local_translations[u]) << sk().names[u];
  }
  for (const char* n : {"UpperLeg_L", "LowerLeg_R", "Foot_L", "UpperArm_L", "LowerArm_R", "Hand_R"})
    EXPECT_LT(geodesic_angle(pose.local_rotations[static_cast<size_t>(J(n))],
                             before.local_rotations[static_cast<size_t>(J(n))]),
              1e-12)
        << n;
  // The correction is spread: the spine bends, the hips move less than the head did.
  const Vec3 hips_moved = pos(g, "Hips") - forward_kinematics(sk(), before).positions[static_cast<size_t>(J("Hips"))];
  EXPECT_LT(hips_moved.norm(), 0.75 * 0.1281);
  EXPECT_GT(geodesic_angle(pose.local_rotations[static_cast<size_t>(J("Chest"))],
                           before.local_rotations[static_cast<size_t>(J("Chest"))]),
            0.01);
}

TEST(BodySolver, NoiseOnTheRawHeadIsTakenUpAboveTheHips) {
  // head_body_m where the network has the head; head_m 3 mm off horizontally (tracker noise):
  // the Head joint goes to head_m, the hips stay (within 0.1 mm).
  Pose pose = walk().frames[10];
  GlobalPose g = forward_kinematics(sk(), pose);
  const Vec3 hips = pos(g, "Hips");
  TrackedTargets t;
  t.head_valid = true;
  t.head_body_m = pos(g, "Head");
  t.head_m = t.head_body_m + Vec3(0.002, 0.0, 0.002);
  t.head_rotation = g.rotations[static_cast<size_t>(J("Head"))];
  (void)solve_tracked_body(sk(), *find_upper_body(sk()), {}, t, pose, g);
  EXPECT_LT((pos(g, "Head") - t.head_m).norm(), 1e-6);
  EXPECT_LT((pos(g, "Hips") - hips).norm(), 1e-4);
}

TEST(BodySolver, ATrackedHipsStaysOnItsTrackerAndTheSpineCarriesTheHead) {
  // Issue 44 item 6: a hips tracker 2 cm from the network's Hips and the headset 3 cm from its
  // Head (both within what the spine can bend to): both joints land on their trackers, the legs
  // keep their local rotations.
  Pose pose = walk().frames[30];
  GlobalPose g = forward_kinematics(sk(), pose);
  const Pose before = pose;
  TrackedTargets t;
  t.hips_valid = true;
  t.hips_m = pos(g, "Hips") + Vec3(0.015, -0.01, 0.01);
  t.head_valid = true;
  t.head_m = pos(g, "Head") + Vec3(-0.01, -0.015, 0.02);
  t.head_body_m = t.head_m;
  t.head_rotation = g.rotations[static_cast<size_t>(J("Head"))];
  const BodySolverResult r = solve_tracked_body(sk(), *find_upper_body(sk()), {}, t, pose, g);
  EXPECT_LT(r.head_error_m, 1e-6);
  // The spine took the head's correction but for millimetres: what it cannot do at first order
  // (shorten the torso for a head lower than the hips allow) goes to the Hips.
  EXPECT_LT((pos(g, "Hips") - t.hips_m).norm(), 0.003);
  for (const char* n : {"UpperLeg_L", "LowerLeg_R", "Foot_L"})
    EXPECT_LT(geodesic_angle(pose.local_rotations[static_cast<size_t>(J(n))],
                             before.local_rotations[static_cast<size_t>(J(n))]),
              1e-12)
        << n;
  // Without the hips tracker the same head correction moves the Hips by centimetres.
  Pose free_pose = before;
  GlobalPose free_g = forward_kinematics(sk(), free_pose);
  TrackedTargets head_only = t;
  head_only.hips_valid = false;
  (void)solve_tracked_body(sk(), *find_upper_body(sk()), {}, head_only, free_pose, free_g);
  EXPECT_GT((pos(free_g, "Hips") - forward_kinematics(sk(), before).positions[static_cast<size_t>(J("Hips"))]).norm(),
            0.01);
}

TEST(BodySolver, StretchedArmReachesItsTrackerAndTheHeadStaysOnItsOwn) {
  Pose pose = walk().frames[30];
  GlobalPose g = forward_kinematics(sk(), pose);
  TrackedTargets t;
  t.head_valid = true;
  t.head_m = t.head_body_m = pos(g, "Head");
  t.head_rotation = g.rotations[static_cast<size_t>(J("Head"))];
  // The right hand 9 cm beyond the arm's reach, out to the side and forward.
  const Vec3 shoulder = pos(g, "UpperArm_R");
  const Vec3 out = (pos(g, "UpperArm_R") - pos(g, "UpperArm_L")).normalized();
  const Vec3 dir = (out + Vec3(0, 0.3, 0) + 0.5 * (out.cross(Vec3::UnitY()))).normalized();
  t.hand_valid = {false, true};
  t.hand_m[1] = shoulder + (arm_length(1) + 0.09) * dir;

  // Two-bone IK alone cannot reach it (so the test below can fail).
  {
    Pose p2 = pose;
    GlobalPose g2 = g;
    TwoBoneTarget target;
    target.position_m = t.hand_m[1];
    const TwoBoneResult r = solve_two_bone_ik(sk(), *find_two_bone_chain(sk(), "UpperArm_R", "LowerArm_R", "Hand_R"),
                                              target, p2, g2);
    EXPECT_GT(r.error_m, 0.08);
  }
  solve_all(t, pose, g);
  EXPECT_LT((pos(g, "Hand_R") - t.hand_m[1]).norm(), 0.01);  // issue 10: <= 1 cm at full reach
  EXPECT_LT((pos(g, "Head") - t.head_m).norm(), 1e-6);
  // The shoulder moved toward the target, not just the hips.
  EXPECT_GT((pos(g, "UpperArm_R") - shoulder).dot(dir), 0.08);
}

TEST(BodySolver, ASmoothPathThroughFullReachGivesASmoothArmWithoutFlips) {
  // The right hand sweeps from bent to 6 cm beyond reach and back in 60 steps of under 1 cm; the
  // solved elbow and shoulder must move by no more than a few times the hand's step, every step.
  const Pose start = walk().frames[30];
  const GlobalPose g0 = forward_kinematics(sk(), start);
  const Vec3 shoulder = pos(g0, "UpperArm_R");
  const Vec3 dir = (pos(g0, "UpperArm_R") - pos(g0, "UpperArm_L")).normalized();
  const Vec3 pole_side = Vec3(0, -1, 0);
  Vec3 last_elbow = Vec3::Zero(), last_shoulder = Vec3::Zero(), last_hand = Vec3::Zero();
  double worst_ratio = 0.0;
  for (int k = 0; k <= 60; ++k) {
    const double u = 0.5 - 0.5 * std::cos(2.0 * M_PI * k / 60.0);  // 0 -> 1 -> 0
    const double reach = (0.6 + 0.4 * u) * arm_length(1) + 0.06 * u;
    Pose pose = start;
    GlobalPose g = g0;
    TrackedTargets t;
    t.head_valid = true;
    t.head_m = t.head_body_m = pos(g0, "Head");
    t.head_rotation = g0.rotations[static_cast<size_t>(J("Head"))];
    t.hand_valid = {false, true};
    t.hand_m[1] = shoulder + reach * (dir + 0.2 * pole_side).normalized();
    solve_all(t, pose, g);
    EXPECT_LT((pos(g, "Hand_R") - t.hand_m[1]).norm(), 0.01) << "step " << k;
    if (k > 0) {
      const double hand_step = (t.hand_m[1] - last_hand).norm();
      const double step = std::max((pos(g, "LowerArm_R") - last_elbow).norm(), (pos(g, "UpperArm_R") - last_shoulder).norm());
      if (hand_step > 1e-4) worst_ratio = std::max(worst_ratio, step / hand_step);
    }
    last_elbow = pos(g, "LowerArm_R");
    last_shoulder = pos(g, "UpperArm_R");
    last_hand = t.hand_m[1];
  }
  EXPECT_LT(worst_ratio, 10.0);  // an elbow flip moves the elbow ~20 cm for a sub-cm hand step
}

// The reach slack (TrackedTargets::hand_slack_m, a noisy hand's): a hand 1.5 cm beyond the arm's
// reach moves nothing with 2 cm of slack (the arm stretches, the hand falls 1.5 cm short); with
// 1 cm of slack the body brings the shoulder to within the slack; a hand 9 cm out is chased
// either way; a slack that is not finite or negative counts as none.
TEST(BodySolver, ReachSlackLeavesTheBodyAloneForAHandJustOutOfReach) {
  const Pose start = walk().frames[30];
  const GlobalPose g0 = forward_kinematics(sk(), start);
  const Vec3 shoulder = pos(g0, "UpperArm_R");
  const Vec3 out = (pos(g0, "UpperArm_R") - pos(g0, "UpperArm_L")).normalized();
  const Vec3 dir = (out + Vec3(0, 0.3, 0) + 0.5 * (out.cross(Vec3::UnitY()))).normalized();
  const auto solve = [&](double beyond_m, double slack_m, GlobalPose& g) {
    Pose pose = start;
    g = g0;
    TrackedTargets t;
    t.head_valid = true;
    t.head_m = t.head_body_m = pos(g0, "Head");
    t.head_rotation = g0.rotations[static_cast<size_t>(J("Head"))];
    t.hand_valid = {false, true};
    t.hand_m[1] = shoulder + (arm_length(1) + beyond_m) * dir;
    t.hand_slack_m[1] = slack_m;
    solve_all(t, pose, g);
    return t.hand_m[1];
  };
  GlobalPose g;
  Vec3 hand = solve(0.015, 0.02, g);
  EXPECT_LT((pos(g, "UpperArm_R") - shoulder).norm(), 1e-9);  // the body did not move
  EXPECT_NEAR((pos(g, "Hand_R") - hand).norm(), 0.015, 1e-6);

  hand = solve(0.015, 0.01, g);
  EXPECT_GT((pos(g, "UpperArm_R") - shoulder).dot(dir), 0.003);
  EXPECT_LT((pos(g, "Hand_R") - hand).norm(), 0.0101);

  hand = solve(0.09, 0.02, g);
  EXPECT_GT((pos(g, "UpperArm_R") - shoulder).dot(dir), 0.06);
  EXPECT_LT((pos(g, "Hand_R") - hand).norm(), 0.0201);

  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), -0.5}) {
    GlobalPose none;
    const Vec3 h = solve(0.015, bad, g);
    (void)solve(0.015, 0.0, none);
    EXPECT_LT((pos(g, "UpperArm_R") - pos(none, "UpperArm_R")).norm(), 1e-12) << bad;
    EXPECT_LT((pos(g, "Hand_R") - h).norm(), 0.01) << bad;
  }
}
