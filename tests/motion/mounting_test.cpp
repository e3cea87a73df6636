// Device mounting (motion/mounting.h): transforms, the shipped body reference and the default
// mounting derived from it.
#include "bodyd/motion/mounting.h"

#include "bodyd/motion/bvh.h"
#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

namespace bodyd {
namespace {

double deg(double rad) { return rad * 180.0 / M_PI; }

Quat random_rotation(std::mt19937_64& g) {
  std::normal_distribution<double> n;
  Quat q(n(g), n(g), n(g), n(g));
  return q.normalized();
}

TEST(Mounting, DeviceToJointUndoesJointToDevice) {
  std::mt19937_64 g(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    const RigidTransform T{Vec3(u(g), u(g), u(g)) * 0.2, random_rotation(g)};
    TrackerSample joint{123, Role::LeftHand, true, Vec3(u(g), 1.0 + u(g), u(g)), random_rotation(g), PoseFrame::Joint};
    const TrackerSample device = joint_to_device(joint, T);
    EXPECT_EQ(device.frame, PoseFrame::Device);
    const TrackerSample back = device_to_joint(device, T);
    EXPECT_EQ(back.frame, PoseFrame::Joint);
    EXPECT_LT((back.position_m - joint.position_m).norm(), 1e-12);
    EXPECT_LT(geodesic_angle(back.rotation, joint.rotation), 1e-9);
    // The definition: T_world_joint = T_world_device * T_device_joint.
    EXPECT_LT((device.position_m + device.rotation * T.position_m - joint.position_m).norm(), 1e-12);
  }
}

TEST(Mounting, JointAndInvalidSamplesPassThroughUnchanged) {
  const RigidTransform T{Vec3(0.1, 0.2, 0.3), Quat(Eigen::AngleAxisd(0.5, Vec3::UnitX()))};
  const TrackerSample joint{5, Role::Head, true, Vec3(0, 1.6, 0), Quat::Identity(), PoseFrame::Joint};
  const TrackerSample out = device_to_joint(joint, T);
  EXPECT_EQ(out.position_m, joint.position_m);
  EXPECT_EQ(out.frame, PoseFrame::Joint);
  TrackerSample lost{5, Role::Head, false, Vec3::Zero(), Quat::Identity(), PoseFrame::Device};
  EXPECT_EQ(device_to_joint(lost, T).frame, PoseFrame::Device);
}

TEST(Mounting, ComposeAndInverse) {
  std::mt19937_64 g(3);
  for (int i = 0; i < 100; ++i) {
    const RigidTransform A{Vec3::Random(), random_rotation(g)};
    const RigidTransform I = compose(A, inverse(A));
    EXPECT_LT(I.position_m.norm(), 1e-12);
    EXPECT_LT(geodesic_angle(I.rotation, Quat::Identity()), 1e-9);
  }
}

BodyReference shipped_reference() { return read_body_reference(test::source_dir() / "data" / "body-reference.json"); }

// The default head mounting, derived from the measured reference, against two values known
// independently of it: the rig's head axes (+X up, +Y forward: the skeleton's Head joint, see
// docs/conventions.md) seen from a headset that looks along its -Z, and the typical eye offset.
TEST(Mounting, DefaultHeadMountingAgreesWithTheRigsHeadAxes) {
  const Mounting m = default_mounting(shipped_reference());
  const RigidTransform& head = m.T_device_joint[static_cast<int>(Role::Head)];
  EXPECT_LT((head.position_m - Vec3(0.0, -0.10, 0.08)).norm(), 1e-12);
  // The rig's head axes turned to a device that looks along -Z: local X -> +Y, local Y -> -Z.
  Mat3 rig;
  rig.col(0) = Vec3::UnitY();
  rig.col(1) = -Vec3::UnitZ();
  rig.col(2) = -Vec3::UnitX();
  const double to_rig_deg = deg(geodesic_angle(Quat(rig), head.rotation));
  std::printf("default head mounting: %.2f deg from the rig's head axes\n", to_rig_deg);
  EXPECT_LT(to_rig_deg, 10.0);
  // The joint's +X (up along the neck) is the device's +Y within the measured head pitch.
  const Vec3 up = head.rotation * Vec3::UnitX();
  EXPECT_GT(up.y(), std::cos(30.0 * M_PI / 180.0)) << up.transpose();
  // The joint's +Y (forward) looks where the device looks (-Z), within the same.
  const Vec3 forward = head.rotation * Vec3::UnitY();
  EXPECT_LT(forward.z(), -std::cos(30.0 * M_PI / 180.0)) << forward.transpose();
  EXPECT_LT(std::abs(forward.x()), 0.2) << "the head must not be turned sideways on the headset";
}

TEST(Mounting, DefaultGripPutsTheWristAboveTheGripOfAHangingHand) {
  const Mounting m = default_mounting(shipped_reference());
  for (Role r : {Role::LeftHand, Role::RightHand}) {
    const RigidTransform& T = m.T_device_joint[static_cast<int>(r)];
    EXPECT_NEAR(T.position_m.y(), kGripToWristAlongHandM, 1e-12);
    // The back of the hand: the user's left for the left hand, right for the right (grip +X).
    EXPECT_NEAR(T.position_m.x(), r == Role::LeftHand ? -kGripToWristAcrossPalmM : kGripToWristAcrossPalmM, 1e-12);
  }
}

TEST(BodyReference, JsonRoundTripAndErrorsNameTheField) {
  const BodyReference r = shipped_reference();
  const BodyReference back = parse_body_reference(body_reference_json(r), "round trip");
  EXPECT_LT(geodesic_angle(back.head_in_facing, r.head_in_facing), 1e-12);
  EXPECT_EQ(back.clips, r.clips);
  EXPECT_DOUBLE_EQ(back.head_over_wrist_height, r.head_over_wrist_height);
  try {
    (void)parse_body_reference(R"({"format": "bodyd-body-reference v1", "head_in_facing_xyzw": [0, 0, 0]})", "f.json");
    FAIL() << "accepted a short quaternion";
  } catch (const BodyReferenceError& e) {
    EXPECT_NE(std::string(e.what()).find("f.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("head_in_facing_xyzw"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)parse_body_reference("{", "g.json"), BodyReferenceError);
  EXPECT_THROW((void)parse_body_reference(R"({"format": "other"})", "g.json"), BodyReferenceError);
}

// The shipped file is what bodyd-bvh --reference measures on the training split today: the
// default mounting is derived from the data, not typed in.
TEST(BodyReference, ShippedFileIsTheTrainingSplitsMeasurement) {
  if (!test::have_bandai()) GTEST_SKIP() << "../shared/data/bandai-namco is absent";
  std::ifstream split(test::bandai() / "splits" / "train.txt");
  std::vector<Motion> clips;
  std::string line;
  while (std::getline(split, line))
    if (!line.empty()) clips.push_back(read_bvh(test::bandai() / line));
  const BodyReference measured = measure_body_reference(clips, "train.txt");
  const BodyReference shipped = shipped_reference();
  EXPECT_LT(deg(geodesic_angle(measured.head_in_facing, shipped.head_in_facing)), 1e-6);
  EXPECT_LT(deg(geodesic_angle(measured.hand_in_facing[0], shipped.hand_in_facing[0])), 1e-6);
  EXPECT_LT(deg(geodesic_angle(measured.hand_in_facing[1], shipped.hand_in_facing[1])), 1e-6);
  EXPECT_EQ(measured.clips, shipped.clips);
  EXPECT_NEAR(measured.head_over_wrist_height, shipped.head_over_wrist_height, 1e-9);
}

TEST(Mounting, FacingFromDeviceIsTheHeadingOfTheLineOfSight) {
  // A headset looking along -Z (identity) faces bodyd's -Z: a turn of 180 degrees from +Z.
  const Quat F = facing_from_device(Quat::Identity());
  EXPECT_LT(((F * Vec3::UnitZ()) - Vec3(0, 0, -1)).norm(), 1e-12);
  // Pitch does not change the heading; a yaw does.
  const Quat pitched(Eigen::AngleAxisd(0.4, Vec3::UnitX()));
  EXPECT_LT(((facing_from_device(pitched) * Vec3::UnitZ()) - Vec3(0, 0, -1)).norm(), 1e-12);
  const Quat yawed(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));
  EXPECT_LT(((facing_from_device(yawed) * Vec3::UnitZ()) - Vec3(-1, 0, 0)).norm(), 1e-12);
}

}  // namespace
}  // namespace bodyd
