// The online evaluation with device frames (docs/evaluation.md "Device frames", issue 16 item 6):
// a headset stream of a fixture clip at random mountings, through the default mounting and
// through the calibration pose, against the same clip in joint frames.
#include "bodyd/inference/evaluation.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/simulators/tracker_sim.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

namespace bodyd {
namespace {

const std::filesystem::path kWalk = test::fixtures() / "walk_60.bvh";

BodyReference reference() { return read_body_reference(test::source_dir() / "data" / "body-reference.json"); }

double mpjpe(const EvalReport& r) { return r.methods.front().metrics.mpjpe_cm; }

EvalOptions diffusion_options() {
  EvalOptions o;
  o.methods = {"diffusion"};
  o.model_path = test::source_dir() / "models" / "bodyd-default.safetensors";
  return o;
}

// Five sessions, each with its own mounting (draw_session_mounting: eye +-2 cm, headset pitch
// +-10 deg, grips +-15 deg): the user stands in the calibration pose for its second, then walks.
// Calibrated (mounting and eye offset from that second), the poses are within 10% of the joint-
// frame evaluation of the same walk; the default mounting alone is worse, which says the
// sessions' mountings matter and the calibration is what removes them.
TEST(DeviceFramesEval, CalibratedHeadsetStreamsAtFiveMountingsAreWithinTenPercentOfJointFrames) {
  const BodyReference ref = reference();
  const Mounting defaults = default_mounting(ref);
  EvalOptions joint = diffusion_options();
  const TrackerSource joint_source = [](const Motion& clip, int) {
    SimOptions s;
    s.rate_hz = clip.fps();
    return simulate_trackers(clip, s);
  };
  const double joint_cm = mpjpe(evaluate(std::vector<std::filesystem::path>{kWalk}, joint, joint_source));
  for (std::uint64_t session = 1; session <= 5; ++session) {
    SCOPED_TRACE("session " + std::to_string(session));
    const Mounting truth = draw_session_mounting(defaults, MountingSpread{}, 1000 + session);
    const TrackerSource device_source = [&](const Motion& clip, int) {
      SimOptions s;
      s.rate_hz = clip.fps();
      s.device_mounting = truth;
      return with_calibration_pose(simulate_trackers(clip, s), ref, truth, s.rate_hz, 1.05);
    };
    EvalOptions o = diffusion_options();
    o.device_frames = true;
    o.body_reference = ref;
    o.true_mounting = [&](int) { return truth; };
    o.calibrate_pose = true;
    o.pose_calibration.estimate_eye_offset = true;
    o.pose_calibration.estimate_head_roll = true;  // the ideal pose: every part of the mounting is observable
    const EvalReport calibrated = evaluate(std::vector<std::filesystem::path>{kWalk}, o, device_source);
    ASSERT_EQ(calibrated.pose_calibrated_clips, 1);
    EXPECT_LT(calibrated.calibrated_mounting_error.head_deg, 2.0);
    EXPECT_LT(calibrated.calibrated_mounting_error.grip_deg, 2.0);
    EXPECT_LT(calibrated.calibrated_mounting_error.eye_offset_cm, 1.0);
    EXPECT_LT(mpjpe(calibrated), 1.1 * joint_cm) << "joint frames: " << joint_cm;
    o.calibrate_pose = false;
    const EvalReport uncalibrated = evaluate(std::vector<std::filesystem::path>{kWalk}, o, device_source);
    EXPECT_GT(mpjpe(uncalibrated), mpjpe(calibrated));
  }
}

// The analysis mode: mapped through the true mounting, a device stream scores exactly what the
// joint stream does (the mounting is the only difference between them).
TEST(DeviceFramesEval, TheTrueMountingReproducesTheJointFrameResult) {
  const BodyReference ref = reference();
  const Mounting truth = draw_session_mounting(default_mounting(ref), MountingSpread{}, 77);
  EvalOptions joint;
  joint.methods = {"ik"};
  const auto source = [&](bool device) {
    return [=](const Motion& clip, int) {
      SimOptions s;
      s.rate_hz = clip.fps();
      if (device) s.device_mounting = truth;
      return simulate_trackers(clip, s);
    };
  };
  const double joint_cm = mpjpe(evaluate(std::vector<std::filesystem::path>{kWalk}, joint, source(false)));
  EvalOptions o = joint;
  o.device_frames = true;
  o.body_reference = ref;
  o.true_mounting = [&](int) { return truth; };
  o.oracle_mounting = true;
  EXPECT_NEAR(mpjpe(evaluate(std::vector<std::filesystem::path>{kWalk}, o, source(true))), joint_cm, 1e-6);
}

}  // namespace
}  // namespace bodyd
