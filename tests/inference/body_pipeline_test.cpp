// The body pipeline the daemon and bodyd-eval share (body_pipeline.h): the order of the
// calibrations around the sample conditioning, and what each applies. The daemon's tests
// (tests/daemon: device_frames_test, calibration_test) check the same through its log and status.
#include "bodyd/inference/body_pipeline.h"
#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <random>
#include <vector>

namespace bodyd {
namespace {

// Records what reaches the reconstructor: each sample pushed with the head height in effect then.
class Recording final : public Reconstructor {
 public:
  struct Pushed {
    TrackerSample sample;
    double head_height_m;
  };
  std::string_view name() const override { return "recording"; }
  const Skeleton& skeleton() const override { return skeleton_; }
  void push(const TrackerSample& s) override { pushed.push_back({s, head_height_m_}); }
  bool reconstruct(std::int64_t, BodyPose&) override { return false; }
  void reset() override { ++resets; }
  void set_head_height_m(double h) override {
    head_height_m_ = h;
    ++resets;  // as the reconstructors do
  }
  double head_height_m() const override { return head_height_m_; }

  std::vector<Pushed> pushed;
  int resets = 0;

 private:
  Skeleton skeleton_;
  double head_height_m_ = 1.5;
};

BodyReference reference() { return read_body_reference(test::source_dir() / "data" / "body-reference.json"); }
Skeleton skeleton() { return read_bvh(test::source_dir() / "data" / "demo" / "skeleton.bvh").skeleton; }

// `seconds` of 90 Hz samples (0.5 mm noise) of a person holding the calibration pose with the
// Head joint at `head_y_m`, facing -Z, as devices mounted by `mounting` send them; the hips too
// when `hips` is given (its device's mounting on the joint, the joint where the reference
// standing pose puts it).
std::vector<TrackerSample> still_device_stream(const Mounting& mounting, double head_y_m, double seconds,
                                               std::optional<RigidTransform> hips = std::nullopt) {
  std::array<RigidTransform, kRoleCount> joints = calibration_pose_joints(reference(), Vec3(0.0, head_y_m, 0.0), M_PI);
  const auto h = static_cast<size_t>(Role::Hips);
  const BodyJointsInPose b = body_joints_in_pose(skeleton());
  const Quat F = quat_from_yaw(M_PI);  // facing -Z
  joints[h] = {joints[0].position_m + F * (b.from_head[h] * (head_y_m / StandingHeightOptions{}.stance_ratio)),
               (F * b.in_facing[h]).normalized()};
  std::mt19937_64 g(5);
  std::normal_distribution<double> n(0.0, 0.0005);
  std::vector<TrackerSample> out;
  for (int k = 0; k < static_cast<int>(seconds * 90.0); ++k) {
    const auto t_ns = static_cast<std::int64_t>(std::llround(k * 1e9 / 90.0));
    for (Role r : {Role::Head, Role::LeftHand, Role::RightHand, Role::Hips}) {
      if (r == Role::Hips && !hips) continue;
      const RigidTransform& J = joints[static_cast<size_t>(r)];
      const TrackerSample s{t_ns, r, true, J.position_m + Vec3(n(g), n(g), n(g)), J.rotation, PoseFrame::Joint};
      out.push_back(joint_to_device(s, r == Role::Hips ? *hips : mounting.T_device_joint[static_cast<size_t>(r)]));
    }
  }
  return out;
}

// The default with the headset pitched `pitch_deg` on the head.
Mounting pitched(const Mounting& defaults, double pitch_deg) {
  Mounting m = defaults;
  const Quat turn(Eigen::AngleAxisd(pitch_deg * M_PI / 180, Vec3::UnitX()));
  m.T_device_joint[0].rotation = (turn.conjugate() * m.T_device_joint[0].rotation).normalized();
  m.T_device_joint[0].position_m = turn.conjugate() * m.T_device_joint[0].position_m;
  return m;
}

TEST(BodyPipeline, TheAutoHeightIsAppliedBeforeTheSampleThatCompletesItIsPushed) {
  BodyPipeline pipeline;
  pipeline.start_auto_height();
  Recording recon;
  std::optional<AutoHeightEvent> event;
  std::size_t event_at = 0;
  for (int k = 0; k < 90; ++k) {
    const TrackerSample head{static_cast<std::int64_t>(std::llround(k * 1e9 / 90.0)), Role::Head, true,
                             Vec3(0.0, 1.6, 0.0), Quat::Identity(), PoseFrame::Joint};
    if (SampleEvents e = pipeline.push(head, head.t_ns, recon); e.height) {
      ASSERT_FALSE(event) << "reported twice";
      event = e.height;
      event_at = recon.pushed.size() - 1;
    }
  }
  ASSERT_TRUE(event);
  EXPECT_EQ(event->outcome, AutoHeightEvent::Outcome::Applied);
  EXPECT_NEAR(event->height.head_height_m, 1.6 / StandingHeightOptions{}.stance_ratio, 1e-9);
  EXPECT_FALSE(pipeline.auto_height_running());
  // The sample that completed the still half second counts at the new size, the one before at the old.
  EXPECT_EQ(recon.pushed[event_at].head_height_m, event->height.head_height_m);
  EXPECT_EQ(recon.pushed[event_at - 1].head_height_m, 1.5);
  EXPECT_EQ(recon.pushed[event_at].sample.t_ns, event->height.t_ns);
}

TEST(BodyPipeline, AnImplausibleHeightIsRefusedAndStopsTheAutoHeight) {
  BodyPipeline pipeline;
  pipeline.start_auto_height();
  Recording recon;
  std::optional<AutoHeightEvent> event;
  for (int k = 0; k < 90 && !event; ++k) {
    const TrackerSample head{k * 11'111'111LL, Role::Head, true, Vec3(0.0, 2.7, 0.0), Quat::Identity(), PoseFrame::Joint};  // over limits::kMaxHeadHeightM
    event = pipeline.push(head, head.t_ns, recon).height;
  }
  ASSERT_TRUE(event);
  EXPECT_EQ(event->outcome, AutoHeightEvent::Outcome::Refused);
  EXPECT_FALSE(event->error.empty());
  EXPECT_EQ(recon.head_height_m(), 1.5);
  EXPECT_FALSE(pipeline.auto_height_running());
}

TEST(BodyPipeline, TheStillSecondMeasuresBodyTrackersAndRefinesThePlausibleHeadset) {
  const BodyReference ref = reference();
  const Mounting defaults = default_mounting(ref);
  const RigidTransform strap{Vec3(0.0, 0.05, 0.06), Quat(Eigen::AngleAxisd(0.4, Vec3(0.2, 1.0, 0.1).normalized()))};
  for (double pitch_deg : {7.0, 20.0}) {
    SCOPED_TRACE(pitch_deg);
    BodyPipeline pipeline;
    pipeline.conditioner().set_default_mounting(defaults);
    pipeline.start_still_second(ref, defaults, body_joints_in_pose(skeleton()), /*refine_head=*/true);
    ASSERT_TRUE(pipeline.still_second_running());
    Recording recon;
    std::optional<StillSecondEvent> event;
    int hips_unused = 0;
    for (const TrackerSample& s : still_device_stream(pitched(defaults, pitch_deg), 1.5, 1.5, strap)) {
      const SampleEvents e = pipeline.push(s, s.t_ns, recon);
      if (e.raw.still_second) event = e.raw.still_second;
      if (!e.used) {
        EXPECT_EQ(s.role, Role::Hips);
        EXPECT_FALSE(event) << "a measured body tracker is used";
        ++hips_unused;
      }
    }
    ASSERT_TRUE(event);
    EXPECT_GT(hips_unused, 80);  // a second of them, until the still second measured it
    EXPECT_FALSE(pipeline.still_second_running());
    EXPECT_TRUE(event->body_measured[static_cast<size_t>(Role::Hips)]);
    EXPECT_TRUE(pipeline.conditioner().measured(Role::Hips));
    EXPECT_EQ(recon.resets, 1);  // the body tracker's inputs jumped; the headset's refinement is millimetres
    EXPECT_FALSE(pipeline.conditioner().measured(Role::LeftHand)) << "the controllers keep their defaults";
    if (pitch_deg < BodyPipeline::kMaxStillHeadChangeDeg) {
      EXPECT_EQ(event->head, StillSecondEvent::Head::Refined);
      EXPECT_NEAR(event->head_change_deg, pitch_deg, 0.5);
      EXPECT_TRUE(pipeline.conditioner().measured(Role::Head));
    } else {
      EXPECT_EQ(event->head, StillSecondEvent::Head::TooFar);
      EXPECT_FALSE(pipeline.conditioner().measured(Role::Head));
      EXPECT_TRUE(pipeline.conditioner().mounting().T_device_joint[0].rotation.isApprox(defaults.T_device_joint[0].rotation));
    }
  }
}

TEST(BodyPipeline, TheStillSecondIsLookedForOnlyAtTheSessionsStart) {
  const BodyReference ref = reference();
  const Mounting defaults = default_mounting(ref);
  BodyPipeline pipeline;
  pipeline.conditioner().set_default_mounting(defaults);
  pipeline.start_still_second(ref, defaults, {}, /*refine_head=*/true);
  Recording recon;
  bool expired = false;
  // A walking head (never still) for 11 s, its arrival times 1 s after its own.
  for (int k = 0; k < 11 * 90 && !expired; ++k) {
    const std::int64_t t_ns = std::llround(k * 1e9 / 90.0);
    const TrackerSample head{t_ns, Role::Head, true, Vec3(0.0, 1.6, -1.2 * t_ns * 1e-9), Quat::Identity(), PoseFrame::Device};
    expired = pipeline.observe_raw(head, t_ns + 1'000'000'000, recon).still_second_expired;
    if (expired) {
      EXPECT_GT(t_ns, BodyPipeline::kStillSecondWindowNs);
    }
  }
  EXPECT_TRUE(expired);
  EXPECT_FALSE(pipeline.still_second_running());
}

TEST(BodyPipeline, ACalibrationPoseSetsEveryMountingAndTheHeightAndEndsTheAutoCalibrations) {
  const BodyReference ref = reference();
  const Mounting defaults = default_mounting(ref);
  // An auto height that has not reported by the pose's second (no fallback, a long still stretch).
  StandingHeightOptions slow;
  slow.still_s = 5.0;
  slow.fallback_after_s = 0.0;
  for (bool apply_height : {false, true}) {
    SCOPED_TRACE(apply_height);
    BodyPipeline pipeline;
    pipeline.conditioner().set_default_mounting(defaults);
    pipeline.start_auto_height(slow);
    pipeline.start_still_second(ref, defaults, {}, /*refine_head=*/true);
    // Held from the start (bodyd-eval --calibration-pose), fed before the still second.
    pipeline.hold_calibration_pose(PoseCalibrator(ref, defaults), apply_height);
    Recording recon;
    std::optional<CalibrationPoseEvent> event;
    std::optional<StillSecondEvent> still;
    for (const TrackerSample& s : still_device_stream(pitched(defaults, 7.0), 1.5, 1.2)) {
      const SampleEvents e = pipeline.push(s, s.t_ns, recon);
      EXPECT_FALSE(e.height);
      if (e.raw.calibration_pose) event = e.raw.calibration_pose;
      if (e.raw.still_second) {
        EXPECT_TRUE(event) << "the held pose comes first";
        still = e.raw.still_second;
      }
    }
    ASSERT_TRUE(event);
    EXPECT_TRUE(event->height_error.empty());
    for (Role r : kXrRoles) EXPECT_TRUE(pipeline.conditioner().measured(r));
    EXPECT_GE(recon.resets, 1);
    if (apply_height) {
      EXPECT_NEAR(recon.head_height_m(), event->calibration.head_height_m, 1e-12);
      EXPECT_FALSE(pipeline.auto_height_running());
      EXPECT_FALSE(still) << "the calibration pose ended the still second";
    } else {
      EXPECT_EQ(recon.head_height_m(), 1.5);
      EXPECT_TRUE(pipeline.auto_height_running()) << "nothing superseded it";
      // The same still second, after the pose: the headset's mounting is measured, so it stays.
      ASSERT_TRUE(still);
      EXPECT_EQ(still->head, StillSecondEvent::Head::Kept);
    }
  }
}

}  // namespace
}  // namespace bodyd
