// The reference T-pose and the retargeting to Unity's humanoid (motion/humanoid.h).
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/humanoid.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace bodyd;

namespace {

Motion walk() { return read_bvh(test::fixtures() / "walk_60.bvh"); }

double angle_deg(const Vec3& a, const Vec3& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
}

Vec3 pos(const Skeleton& s, const GlobalPose& g, const char* name) {
  return g.positions[static_cast<size_t>(s.find(name))];
}

// Direction of the bone from joint a to joint b.
Vec3 bone(const Skeleton& s, const GlobalPose& g, const char* a, const char* b) {
  return (pos(s, g, b) - pos(s, g, a)).normalized();
}

Quat random_quat(std::mt19937& rng) {
  std::normal_distribution<double> n;
  return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

// Unity FK of the retargeted pose against the bodyd global pose: worst position error (m) and
// worst rotation error (rad) after undoing the T-pose reference.
std::pair<double, double> fk_error(const Skeleton& s, const UnityRig& rig, const GlobalPose& g) {
  UnityPose u;
  retarget_to_unity(rig, g, u);
  std::array<Vec3, kHumanoidBones.size()> p;
  std::array<Quat, kHumanoidBones.size()> q;
  unity_forward_kinematics(rig, u, p, q);
  double worst_p = 0.0, worst_q = 0.0;
  for (size_t b = 0; b < kHumanoidBones.size(); ++b) {
    const auto j = static_cast<size_t>(rig.joint[b]);
    worst_p = std::max(worst_p, (unity_from_bodyd(p[b]) - g.positions[j]).norm());
    const Quat back = (unity_from_bodyd(q[b]) * rig.tpose_global_inverse[b].conjugate()).normalized();
    worst_q = std::max(worst_q, geodesic_angle(back, g.rotations[j]));
  }
  (void)s;
  return {worst_p, worst_q};
}

// make_rest_pose and make_unity_rig for `s`; the failure says which could not be made, and why.
::testing::AssertionResult make_rest_pose_and_unity_rig(const Skeleton& s, RestPose& rest, UnityRig& rig) {
  std::string error;
  if (!make_rest_pose(s, rest, error)) return ::testing::AssertionFailure() << "rest pose: " << error;
  if (!make_unity_rig(s, rig, error)) return ::testing::AssertionFailure() << "Unity rig: " << error;
  return ::testing::AssertionSuccess();
}

}  // namespace

TEST(RestPose, IsATPoseStandingOnTheFloorFacingPlusZ) {
  const Motion m = walk();
  const Skeleton& s = m.skeleton;
  RestPose rest;
  std::string error;
  ASSERT_TRUE(make_rest_pose(s, rest, error)) << error;
  const GlobalPose& g = rest.global;
  const Vec3 up = Vec3::UnitY(), left = Vec3::UnitX();
  for (auto [a, b] : {std::pair{"Hips", "Spine"}, {"Spine", "Chest"}, {"Chest", "Neck"}, {"Neck", "Head"}})
    EXPECT_LT(angle_deg(bone(s, g, a, b), up), 3.0) << a << "->" << b;
  for (auto [a, b] : {std::pair{"Shoulder_L", "UpperArm_L"}, {"UpperArm_L", "LowerArm_L"}, {"LowerArm_L", "Hand_L"}})
    EXPECT_LT(angle_deg(bone(s, g, a, b), left), 1.0) << a << "->" << b;
  for (auto [a, b] : {std::pair{"Shoulder_R", "UpperArm_R"}, {"UpperArm_R", "LowerArm_R"}, {"LowerArm_R", "Hand_R"}})
    EXPECT_LT(angle_deg(bone(s, g, a, b), -left), 1.0) << a << "->" << b;
  for (const char* side : {"_L", "_R"}) {
    const std::string ul = std::string("UpperLeg") + side, ll = std::string("LowerLeg") + side,
                      ft = std::string("Foot") + side, to = std::string("Toes") + side;
    EXPECT_LT(angle_deg(bone(s, g, ul.c_str(), ll.c_str()), -up), 1.0) << side;
    EXPECT_LT(angle_deg(bone(s, g, ll.c_str(), ft.c_str()), -up), 1.0) << side;
    const double pitch = kRestFootPitchDeg * M_PI / 180.0;
    EXPECT_LT(angle_deg(bone(s, g, ft.c_str(), to.c_str()), Vec3(0, -std::sin(pitch), std::cos(pitch))), 1.0) << side;
    EXPECT_NEAR(pos(s, g, to.c_str()).y(), kRestToesHeightM, 1e-3) << side;
  }
  // Left is +X, the Hips' +Z (the pose message's heading axis) is forward, the root at the origin.
  EXPECT_GT(pos(s, g, "UpperLeg_L").x(), pos(s, g, "UpperLeg_R").x() + 0.1);
  EXPECT_LT(angle_deg(g.rotations[static_cast<size_t>(s.find("Hips"))] * Vec3::UnitZ(), Vec3::UnitZ()), 1e-9);
  EXPECT_NEAR(pos(s, g, "Hips").x(), 0.0, 1e-12);
  EXPECT_NEAR(pos(s, g, "Hips").z(), 0.0, 1e-12);
  // Heights as in the data's standing reference frame (Hips 0.94 m, Head joint 1.42 m; the BVH
  // Hips offset is a clip's world position, z = 4.5 m).
  EXPECT_NEAR(pos(s, g, "Hips").y(), 0.94, 0.03);
  EXPECT_NEAR(pos(s, g, "Head").y(), 1.42, 0.03);
  EXPECT_EQ(rest.offsets[static_cast<size_t>(s.find("Hips"))].x(), 0.0);
  EXPECT_EQ(rest.offsets[static_cast<size_t>(s.find("Hips"))].z(), 0.0);
  // Every other rest offset is the skeleton's.
  for (int j = 2; j < s.size(); ++j) EXPECT_EQ(rest.offsets[static_cast<size_t>(j)], s.offsets[static_cast<size_t>(j)]);
}

// The hinge axes the T-pose table claims, checked against what the data does: in the walk
// clip elbows flex by negative angles about local Y, knees by positive ones. Applied to the
// T-pose, an elbow flexion must bring the hand forward (palms down, hinge vertical) and a knee
// flexion must take the foot backward.
TEST(RestPose, HingesBendTheWayTheDataBends) {
  const Motion m = walk();
  const Skeleton& s = m.skeleton;
  double elbow_min = 0, knee_max = 0;
  for (const Pose& f : m.frames) {
    for (const char* e : {"LowerArm_L", "LowerArm_R"})
      elbow_min = std::min(elbow_min, axis_angle_from_quat(f.local_rotations[static_cast<size_t>(s.find(e))]).y());
    for (const char* k : {"LowerLeg_L", "LowerLeg_R"})
      knee_max = std::max(knee_max, axis_angle_from_quat(f.local_rotations[static_cast<size_t>(s.find(k))]).y());
  }
  ASSERT_LT(elbow_min, -0.3);  // the data's elbows flex about -Y ...
  ASSERT_GT(knee_max, 0.5);    // ... and its knees about +Y
  RestPose rest;
  std::string error;
  ASSERT_TRUE(make_rest_pose(s, rest, error)) << error;
  for (const char* side : {"_L", "_R"}) {
    Pose p{rest.rotations, rest.offsets};
    const auto elbow = static_cast<size_t>(s.find(std::string("LowerArm") + side));
    const auto knee = static_cast<size_t>(s.find(std::string("LowerLeg") + side));
    p.local_rotations[elbow] = rest.rotations[elbow] * Quat(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitY()));
    p.local_rotations[knee] = rest.rotations[knee] * Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));
    const GlobalPose g = forward_kinematics(s, p);
    const Vec3 forearm = bone(s, g, (std::string("LowerArm") + side).c_str(), (std::string("Hand") + side).c_str());
    const Vec3 shin = bone(s, g, (std::string("LowerLeg") + side).c_str(), (std::string("Foot") + side).c_str());
    EXPECT_LT(angle_deg(forearm, Vec3::UnitZ()), 1.0) << side << " elbow flexed 90 degrees points forward";
    EXPECT_LT(angle_deg(shin, -Vec3::UnitZ()), 1.0) << side << " knee flexed 90 degrees points backward";
  }
}

TEST(RestPose, RefusesOtherSkeletons) {
  Skeleton s = walk().skeleton;
  RestPose rest;
  std::string error;
  Skeleton renamed = s;
  renamed.names[static_cast<size_t>(s.find("Toes_R"))] = "RightToe";
  EXPECT_FALSE(make_rest_pose(renamed, rest, error));
  EXPECT_NE(error.find("Toes_R"), std::string::npos) << error;
  Skeleton reparented = s;
  reparented.parents[static_cast<size_t>(s.find("Shoulder_L"))] = s.find("Spine");
  EXPECT_FALSE(make_rest_pose(reparented, rest, error));
  EXPECT_NE(error.find("Shoulder_L"), std::string::npos) << error;
  EXPECT_NE(error.find("Chest"), std::string::npos) << error;
}

TEST(Unity, AxisConversion) {
  // A quarter turn about bodyd's +Y takes +Z to +X; in Unity's axes that takes -Z to +X, a
  // quarter turn about Unity's -Y.
  const Quat q(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));
  const Quat u = unity_from_bodyd(q);
  EXPECT_NEAR(u.x(), 0.0, 1e-15);
  EXPECT_NEAR(u.y(), -std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(u.z(), 0.0, 1e-15);
  EXPECT_NEAR(u.w(), std::sqrt(0.5), 1e-15);
  EXPECT_EQ(unity_from_bodyd(Vec3(1, 2, 3)), Vec3(1, 2, -3));
  // For any rotation, converting then rotating equals rotating then converting.
  std::mt19937 rng(7);
  for (int i = 0; i < 100; ++i) {
    const Quat r = random_quat(rng);
    const Vec3 v(std::normal_distribution<double>()(rng), 1.0, -0.5);
    EXPECT_LT((unity_from_bodyd(Quat(r)) * unity_from_bodyd(v) - unity_from_bodyd(Vec3(r * v))).norm(), 1e-12);
    EXPECT_LT(geodesic_angle(unity_from_bodyd(unity_from_bodyd(r)), r), 1e-12);
  }
}

TEST(Unity, TPoseGivesIdentityRotations) {
  const Skeleton s = walk().skeleton;
  RestPose rest;
  UnityRig rig;
  ASSERT_TRUE(make_rest_pose_and_unity_rig(s, rest, rig));
  // The T-pose turned to face bodyd -Z (Unity +Z) and moved: every local rotation is the identity.
  const Quat turn(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));
  Pose p{rest.rotations, rest.offsets};
  p.local_rotations[0] = turn;
  p.local_translations[0] = Vec3(0.3, 0.0, -1.2);
  const GlobalPose g = forward_kinematics(s, p);
  UnityPose u;
  retarget_to_unity(rig, g, u);
  for (size_t b = 0; b < kHumanoidBones.size(); ++b)
    EXPECT_LT(geodesic_angle(u.local_rotations[b], Quat::Identity()), 1e-9) << kHumanoidBones[b].unity;
  const Vec3 hips = pos(s, g, "Hips");
  EXPECT_LT((u.local_positions[0] - Vec3(hips.x(), hips.y(), -hips.z())).norm(), 1e-12);
  // In the T-pose's bone offsets (Unity axes), the left arm runs along Unity -X, the spine up,
  // the legs down, the feet forward (+Z) and down.
  EXPECT_LT(u.local_positions[7].x(), -0.2);   // LeftLowerArm from LeftUpperArm
  EXPECT_GT(u.local_positions[11].x(), 0.2);   // RightLowerArm
  EXPECT_GT(u.local_positions[3].y(), 0.1);    // Neck
  EXPECT_LT(u.local_positions[14].y(), -0.3);  // LeftLowerLeg
  EXPECT_GT(u.local_positions[16].z(), 0.05);  // LeftToes from LeftFoot
  EXPECT_LT(u.local_positions[16].y(), -0.05);
  EXPECT_GT(u.local_positions[13].x(), -0.15); // LeftUpperLeg: left of the hips is Unity -X
  EXPECT_LT(u.local_positions[13].x(), -0.03);

  // Facing bodyd's +Z (the rest pose itself): only the Hips turn, half a turn about +Y.
  retarget_to_unity(rig, rest.global, u);
  EXPECT_LT(geodesic_angle(u.local_rotations[0], Quat(Eigen::AngleAxisd(M_PI, Vec3::UnitY()))), 1e-9);
  for (size_t b = 1; b < kHumanoidBones.size(); ++b)
    EXPECT_LT(geodesic_angle(u.local_rotations[b], Quat::Identity()), 1e-9) << kHumanoidBones[b].unity;
}

TEST(Unity, ForwardKinematicsReproducesEveryFrame) {
  const Motion m = walk();
  UnityRig rig;
  std::string error;
  ASSERT_TRUE(make_unity_rig(m.skeleton, rig, error)) << error;
  double worst_p = 0, worst_q = 0;
  for (const Pose& f : m.frames) {
    const auto [e_p, e_q] = fk_error(m.skeleton, rig, forward_kinematics(m.skeleton, f));
    worst_p = std::max(worst_p, e_p);
    worst_q = std::max(worst_q, e_q);
  }
  // Metres. Not 1e-9: every joint of the data has position channels, which stretch bones by
  // up to 0.2 micrometres against the rest offsets the rig uses (the VMC test allows 1 mm).
  EXPECT_LT(worst_p, 1e-6);
  EXPECT_LT(worst_q, 1e-9);  // radians
}

TEST(Unity, HardRotations) {
  const Skeleton s = walk().skeleton;
  UnityRig rig;
  std::string error;
  ASSERT_TRUE(make_unity_rig(s, rig, error)) << error;
  std::mt19937 rng(11);
  Pose p = rest_pose(s);
  for (int trial = 0; trial < 50; ++trial) {
    for (size_t j = 0; j < p.local_rotations.size(); ++j) {
      switch ((trial + j) % 4) {
        case 0: p.local_rotations[j] = Quat(Eigen::AngleAxisd(M_PI, Vec3(1, 2, 3).normalized())); break;  // w = 0
        case 1: p.local_rotations[j] = Quat(1e-9, 1, 0, 0).normalized(); break;                          // w ~ 0
        case 2: p.local_rotations[j] = quat_from_axis_angle(Vec3(1e-10, 0, 0)); break;                   // tiny
        default: p.local_rotations[j] = random_quat(rng);
      }
    }
    p.local_translations[0] = Vec3(trial * 0.1, 0, -trial * 0.2);
    const auto [e_p, e_q] = fk_error(s, rig, forward_kinematics(s, p));
    EXPECT_LT(e_p, 1e-9) << trial;
    EXPECT_LT(e_q, 1e-9) << trial;
  }
}

TEST(Unity, ScaledSkeletonKeepsTheConventions) {
  Skeleton s = walk().skeleton;
  for (auto& o : s.offsets) o *= 1.2;  // a user 20% taller
  UnityRig rig, rig1;
  std::string error;
  ASSERT_TRUE(make_unity_rig(s, rig, error)) << error;
  ASSERT_TRUE(make_unity_rig(walk().skeleton, rig1, error)) << error;
  for (size_t b = 1; b < kHumanoidBones.size(); ++b) {
    EXPECT_LT((rig.tpose_local_position[b] - 1.2 * rig1.tpose_local_position[b]).norm(), 1e-9) << kHumanoidBones[b].unity;
    EXPECT_LT(geodesic_angle(rig.tpose_global_inverse[b], rig1.tpose_global_inverse[b]), 1e-12);
  }
}

// Issue 20 item 9: the general recipe of docs/protocol.md ("Unity", per pose) for an avatar
// with its own bone axes, its own size and a placed root. The avatar's T-pose is bodyd's turned
// to face Unity +Z and scaled by k, but each bone's frame is an arbitrary rotation X_b of it
// (A[b] = Y180 * U(T[j]) * X_b): forward kinematics over the avatar's own hierarchy with
//   bone.rotation = root.rotation * D * Y180 * A[b],   D = U(R[j]) * Inverse(U(T[j]))
// and the hips placed by the documented scaling must put every joint at the root's transform of
// k * U(the joint's bodyd position), i.e. the user's motion in Unity axes at the avatar's size.
TEST(Unity, DocumentedRecipeDrivesAnAvatarWithItsOwnBoneAxesAndSize) {
  const Motion m = walk();
  const Skeleton& s = m.skeleton;
  RestPose rest;
  UnityRig rig;
  ASSERT_TRUE(make_rest_pose_and_unity_rig(s, rest, rig));
  const Quat y180(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));
  std::mt19937 rng(20);
  const double k = 1.3;  // the avatar is 30 % larger than the user
  const Quat root_rotation = random_quat(rng);
  const Vec3 root_position(0.5, -0.2, 2.0);
  constexpr size_t n = kHumanoidBones.size();
  // The avatar, read in its T-pose as the doc says: A[b] relative to its root, its bones'
  // offsets in their parents' frames, hAvatar, fAvatar.
  std::array<Quat, n> avatar_rotation{};
  std::array<Vec3, n> avatar_tpose_position{}, avatar_offset{};
  for (size_t b = 0; b < n; ++b) {
    const auto j = static_cast<size_t>(rig.joint[b]);
    avatar_rotation[b] = (y180 * unity_from_bodyd(rest.global.rotations[j]) * random_quat(rng)).normalized();
    avatar_tpose_position[b] = k * (y180 * unity_from_bodyd(rest.global.positions[j]));
  }
  for (size_t b = 1; b < n; ++b) {
    const auto p = static_cast<size_t>(rig.parent[b]);
    avatar_offset[b] = avatar_rotation[p].conjugate() * (avatar_tpose_position[b] - avatar_tpose_position[p]);
  }
  const auto toes_l = static_cast<size_t>(s.find("Toes_L")), toes_r = static_cast<size_t>(s.find("Toes_R"));
  const double h_user = rest.global.positions[static_cast<size_t>(s.find("Hips"))].y();
  const double f_user = std::min(rest.global.positions[toes_l].y(), rest.global.positions[toes_r].y());
  const double h_avatar = avatar_tpose_position[0].y(), f_avatar = k * f_user;
  const double scale = (h_avatar - f_avatar) / (h_user - f_user);
  EXPECT_NEAR(scale, k, 1e-12);

  double worst = 0.0;
  for (const Pose& frame : m.frames) {
    const GlobalPose g = forward_kinematics(s, frame);
    std::array<Quat, n> world{};
    std::array<Vec3, n> position{};
    for (size_t b = 0; b < n; ++b) {
      const auto j = static_cast<size_t>(rig.joint[b]);
      const Quat d = unity_from_bodyd(g.rotations[j]) * unity_from_bodyd(rest.global.rotations[j]).conjugate();
      world[b] = root_rotation * d * y180 * avatar_rotation[b];
      if (b == 0) {
        const Vec3 p = unity_from_bodyd(g.positions[j]);
        position[b] = root_position + root_rotation * Vec3(scale * p.x(), f_avatar + scale * (p.y() - f_user), scale * p.z());
      } else {
        const auto p = static_cast<size_t>(rig.parent[b]);
        position[b] = position[p] + world[p] * avatar_offset[b];
      }
      const Vec3 expected = root_position + root_rotation * (k * unity_from_bodyd(g.positions[j]));
      worst = std::max(worst, (position[b] - expected).norm());
    }
  }
  EXPECT_LT(worst, 1e-5);  // metres (the data's position channels stretch bones by micrometres)

  // The reference T-pose (facing bodyd +Z) turns the avatar to face its root's -Z.
  const Quat d0 = Quat::Identity();
  const Quat hips_world = d0 * y180 * avatar_rotation[0];
  const Vec3 forward_in_tpose = avatar_rotation[0].conjugate() * Vec3::UnitZ();  // the avatar's +Z in the Hips frame
  EXPECT_LT((hips_world * forward_in_tpose - Vec3(0, 0, -1)).norm(), 1e-9);
}
