#include "bodyd/inference/ik.h"

#include "bodyd/inference/factory.h"
#include "bodyd/motion/bvh.h"

#include "../test_paths.h"
#include "bodyd/test/alloc_counter.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace bodyd;

namespace {

constexpr std::int64_t kFrameNs = 33'333'333;

const Skeleton& data_skeleton() {
  static const Skeleton s = read_bvh(test::fixtures() / "bow_30.bvh").skeleton;
  return s;
}

// The reference standing pose moved to (x, z), turned by `yaw`, scaled by `scale` (world positions).
struct Placed {
  GlobalPose global;
};
Placed place(const StandingReference& ref, double x, double z, double yaw, double scale = 1.0) {
  const Quat r = quat_from_yaw(yaw);
  Placed p;
  p.global = ref.global;
  for (size_t j = 0; j < p.global.positions.size(); ++j) {
    p.global.positions[j] = scale * (r * ref.global.positions[j] + Vec3(x, 0, z));
    p.global.rotations[j] = (r * ref.global.rotations[j]).normalized();
  }
  return p;
}

TrackerSample tracker(const Skeleton& s, const GlobalPose& g, Role role, std::int64_t t_ns, bool valid = true) {
  const auto j = static_cast<size_t>(s.find(role_joint_name(role)));
  TrackerSample out;
  out.role = role;
  out.t_ns = t_ns;
  out.valid = valid;
  if (valid) {
    out.position_m = g.positions[j];
    out.rotation = g.rotations[j];
  }
  return out;
}

void push_all(Reconstructor& r, const Skeleton& s, const GlobalPose& g, std::int64_t t_ns) {
  for (Role role : kXrRoles) r.push(tracker(s, g, role, t_ns));
}

}  // namespace

TEST(StandingReference, StandsUprightFacingPlusZOnTheFloor) {
  const StandingReference ref = standing_reference(data_skeleton());
  const Skeleton& s = data_skeleton();
  const auto pos = [&](const char* name) { return ref.global.positions[static_cast<size_t>(s.find(name))]; };
  // Facing +Z: the left hip is on +X, the hip line has no Z component.
  const Vec3 hips_line = pos("UpperLeg_L") - pos("UpperLeg_R");
  EXPECT_GT(hips_line.x(), 0.05);
  EXPECT_NEAR(hips_line.z(), 0.0, 1e-9);
  EXPECT_NEAR(pos("Hips").x(), 0.0, 1e-12);
  EXPECT_NEAR(pos("Hips").z(), 0.0, 1e-12);
  EXPECT_NEAR(std::min(pos("Toes_L").y(), pos("Toes_R").y()), 0.045, 1e-9);
  // Standing: head high above the hips, hips above the knees above the feet, hands below the chest.
  EXPECT_GT(ref.head_height_m, 1.35);
  EXPECT_LT(ref.head_height_m, 1.50);
  EXPECT_DOUBLE_EQ(standing_head_height_m(s), ref.head_height_m);
  EXPECT_GT(pos("Hips").y(), pos("LowerLeg_L").y() + 0.3);
  EXPECT_GT(pos("LowerLeg_L").y(), pos("Foot_L").y() + 0.3);
  EXPECT_LT(pos("Hand_L").y(), pos("Chest").y());
  EXPECT_LT(pos("Hand_R").y(), pos("Chest").y());
  // The head's local axes found for heading map to +Z and +Y.
  const Quat& gh = ref.global.rotations[static_cast<size_t>(s.find("Head"))];
  EXPECT_LT((gh * ref.head_forward_local - Vec3::UnitZ()).norm(), 1e-12);
  EXPECT_LT((gh * ref.head_up_local - Vec3::UnitY()).norm(), 1e-12);
}

TEST(StandingReference, HeadYawSurvivesLookingStraightUpOrDown) {
  const StandingReference ref = standing_reference(data_skeleton());
  const Quat g_head = ref.global.rotations[static_cast<size_t>(data_skeleton().find("Head"))];
  for (double yaw_deg : {-170.0, -45.0, 0.0, 30.0, 179.0}) {
    for (double pitch_deg : {-90.0, -60.0, 0.0, 45.0, 89.0, 90.0}) {
      const Quat q = quat_from_yaw(yaw_deg * M_PI / 180.0) *
                     Quat(Eigen::AngleAxisd(pitch_deg * M_PI / 180.0, Vec3::UnitX())) * g_head;
      const double got = head_yaw_rad(q, ref) * 180.0 / M_PI;
      EXPECT_NEAR(std::remainder(got - yaw_deg, 360.0), 0.0, 1e-7) << "yaw " << yaw_deg << " pitch " << pitch_deg;
    }
  }
}

TEST(StandingReference, UnknownSkeletonIsAClearError) {
  Skeleton s = data_skeleton();
  s.names[static_cast<size_t>(s.find("Hand_L"))] = "LeftPaw";
  try {
    (void)standing_reference(s);
    FAIL() << "no error";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("LeftPaw"), std::string::npos) << e.what();
  }
  EXPECT_THROW(IkReconstructor{s}, UserError);
  EXPECT_THROW((void)make_reconstructor("ik", {}, &s), ReconstructorError);
}

TEST(IkReconstructor, ReproducesTheStandingPoseAnywhereItStands) {
  const Skeleton& s = data_skeleton();
  IkReconstructor ik(s);
  EXPECT_EQ(ik.name(), "ik");
  const Placed p = place(ik.reference(), 1.5, -2.0, 2.0);
  push_all(ik, s, p.global, 0);
  BodyPose out;
  ASSERT_TRUE(ik.reconstruct(0, out));
  EXPECT_EQ(out.t_ns, 0);
  for (int j = 1; j < s.size(); ++j) {
    const auto jj = static_cast<size_t>(j);
    EXPECT_LT((out.global.positions[jj] - p.global.positions[jj]).norm(), 1e-6) << s.names[jj];
    EXPECT_LT(geodesic_angle(out.global.rotations[jj], p.global.rotations[jj]), 1e-6) << s.names[jj];
  }
  EXPECT_TRUE(out.foot_contact[0] && out.foot_contact[1]);
  EXPECT_TRUE(out.tracker_valid[0] && out.tracker_valid[1] && out.tracker_valid[2]);
  // The output is forward kinematics of the output pose.
  const GlobalPose fk = forward_kinematics(ik.skeleton(), out.pose);
  for (size_t j = 0; j < fk.positions.size(); ++j) EXPECT_LT((fk.positions[j] - out.global.positions[j]).norm(), 1e-12);
}

TEST(IkReconstructor, FollowsTheTrackers) {
  // A crouching, bowing head and hands held out: the head and hands are where the trackers are.
  const Skeleton& s = data_skeleton();
  IkReconstructor ik(s);
  Placed p = place(ik.reference(), 0.2, 0.1, -0.7);
  const auto head = static_cast<size_t>(s.find("Head"));
  p.global.positions[head] += Vec3(0.05, -0.3, 0.1);
  p.global.rotations[head] = (Quat(Eigen::AngleAxisd(0.6, Vec3(1, 0, 0.3).normalized())) * p.global.rotations[head]).normalized();
  // Within reach (body frame: +X left, +Z forward), held out in front.
  const Quat r = quat_from_yaw(-0.7);
  p.global.positions[static_cast<size_t>(s.find("Hand_L"))] = p.global.positions[head] + r * Vec3(0.2, -0.3, 0.2);
  p.global.positions[static_cast<size_t>(s.find("Hand_R"))] = p.global.positions[head] + r * Vec3(-0.15, -0.1, 0.3);
  push_all(ik, s, p.global, 5 * kFrameNs);
  BodyPose out;
  ASSERT_TRUE(ik.reconstruct(5 * kFrameNs, out));
  for (const char* name : {"Head", "Hand_L", "Hand_R"}) {
    const auto j = static_cast<size_t>(s.find(name));
    EXPECT_LT((out.global.positions[j] - p.global.positions[j]).norm(), 1e-6) << name;
    EXPECT_LT(geodesic_angle(out.global.rotations[j], p.global.rotations[j]), 1e-6) << name;
  }
  // Legs straight as in the reference: the leg joints' local rotations are the reference's.
  for (const char* name : {"UpperLeg_L", "LowerLeg_L", "Foot_R", "Toes_R"}) {
    const auto j = static_cast<size_t>(s.find(name));
    EXPECT_LT(geodesic_angle(out.pose.local_rotations[j], ik.reference().pose.local_rotations[j]), 1e-9) << name;
  }
}

TEST(IkReconstructor, NothingBeforeTheFirstHeadAndHoldsALostHead) {
  const Skeleton& s = data_skeleton();
  IkReconstructor ik(s);
  const Placed p = place(ik.reference(), 0, 0, 0.5);
  BodyPose out;
  out.t_ns = -7;
  EXPECT_FALSE(ik.reconstruct(0, out));
  ik.push(tracker(s, p.global, Role::LeftHand, 0));
  ik.push(tracker(s, p.global, Role::RightHand, 0));
  EXPECT_FALSE(ik.reconstruct(kFrameNs, out));
  EXPECT_EQ(out.t_ns, -7);  // unchanged
  ik.push(tracker(s, p.global, Role::Head, 2 * kFrameNs));
  EXPECT_FALSE(ik.reconstruct(2 * kFrameNs - 1, out));  // the head sample is in the future
  ASSERT_TRUE(ik.reconstruct(2 * kFrameNs, out));
  const auto head = static_cast<size_t>(s.find("Head"));
  const Vec3 head_pos = out.global.positions[head];

  // Head lost: the last head pose is held and reported as not observed.
  ik.push(tracker(s, p.global, Role::Head, 3 * kFrameNs, false));
  ASSERT_TRUE(ik.reconstruct(3 * kFrameNs, out));
  EXPECT_FALSE(out.tracker_valid[0]);
  EXPECT_LT((out.global.positions[head] - head_pos).norm(), 1e-12);
  // Long after everything stopped: still the held head; hands timed out.
  ASSERT_TRUE(ik.reconstruct(100 * kFrameNs, out));
  EXPECT_FALSE(out.tracker_valid[0] || out.tracker_valid[1] || out.tracker_valid[2]);

  ik.reset();
  EXPECT_FALSE(ik.reconstruct(101 * kFrameNs, out));
}

TEST(IkReconstructor, LostHandHangsInTheReferencePose) {
  const Skeleton& s = data_skeleton();
  IkReconstructor ik(s);
  Placed p = place(ik.reference(), 0, 0, 0);
  p.global.positions[static_cast<size_t>(s.find("Hand_L"))] += Vec3(0.1, 0.4, 0.3);
  ik.push(tracker(s, p.global, Role::Head, 0));
  ik.push(tracker(s, p.global, Role::LeftHand, 0, false));
  ik.push(tracker(s, p.global, Role::RightHand, 0));
  BodyPose out;
  ASSERT_TRUE(ik.reconstruct(0, out));
  EXPECT_TRUE(out.tracker_valid[0]);
  EXPECT_FALSE(out.tracker_valid[1]);
  EXPECT_TRUE(out.tracker_valid[2]);
  for (const char* name : {"UpperArm_L", "LowerArm_L", "Hand_L"}) {
    const auto j = static_cast<size_t>(s.find(name));
    EXPECT_LT(geodesic_angle(out.pose.local_rotations[j], ik.reference().pose.local_rotations[j]), 1e-9) << name;
  }
}

TEST(IkReconstructor, UserHeightScalesInAndOut) {
  const Skeleton& s = data_skeleton();
  IkReconstructor ik(s);
  const double model_h = ik.reference().head_height_m;
  EXPECT_DOUBLE_EQ(ik.head_height_m(), model_h);
  ik.set_head_height_m(2.0 * model_h);
  EXPECT_DOUBLE_EQ(ik.head_height_m(), 2.0 * model_h);
  for (size_t j = 0; j < s.offsets.size(); ++j) EXPECT_LT((ik.skeleton().offsets[j] - 2.0 * s.offsets[j]).norm(), 1e-12);
  // A user twice the size standing like the reference: the reference, twice the size.
  const Placed p = place(ik.reference(), 0.4, 0.3, 1.0, 2.0);
  push_all(ik, s, p.global, 0);
  BodyPose out;
  ASSERT_TRUE(ik.reconstruct(0, out));
  for (int j = 1; j < s.size(); ++j) {
    const auto jj = static_cast<size_t>(j);
    EXPECT_LT((out.global.positions[jj] - p.global.positions[jj]).norm(), 2e-6) << s.names[jj];
  }
  ik.set_head_height_m(0.0);
  EXPECT_DOUBLE_EQ(ik.head_height_m(), model_h);
  EXPECT_LT((ik.skeleton().offsets[5] - s.offsets[5]).norm(), 1e-12);
}

TEST(IkReconstructor, ReconstructDoesNotAllocateOnceWarm) {
  const Skeleton& s = data_skeleton();
  IkReconstructor ik(s);
  const Placed p = place(ik.reference(), 0, 0, 0.3);
  BodyPose out;
  push_all(ik, s, p.global, 0);
  ASSERT_TRUE(ik.reconstruct(0, out));
  std::int64_t allocations = 0;
  {
    test::AllocationCounter counter;
    for (int f = 1; f < 50; ++f) {
      push_all(ik, s, p.global, f * kFrameNs);
      (void)ik.reconstruct(f * kFrameNs, out);
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
}

TEST(Factory, MakesIkAndExplainsWhatIsMissing) {
  const auto ik = make_reconstructor("ik", {}, &data_skeleton());
  ASSERT_NE(ik, nullptr);
  EXPECT_EQ(ik->name(), "ik");
  EXPECT_EQ(ik->skeleton().names, data_skeleton().names);
  try {
    (void)make_reconstructor("ik", {}, nullptr);
    FAIL();
  } catch (const ReconstructorError& e) {
    EXPECT_NE(std::string(e.what()).find("skeleton"), std::string::npos);
  }
  try {
    (void)make_reconstructor("magic", {}, &data_skeleton());
    FAIL();
  } catch (const ReconstructorError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown reconstruction method 'magic'"), std::string::npos) << e.what();
  }
}
