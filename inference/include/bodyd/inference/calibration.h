// User-height calibration from the head tracker (docs/daemon.md, "Calibration").
//
// The reconstructors scale by the user's standing head height (Reconstructor::set_head_height_m).
// Two ways to measure it, both ending in calibrate_from_head_height():
//  - on request: the control socket's {"cmd":"calibrate","from":"head"} takes the head's
//    current height (standing_height_from_head(), the same stance correction as below);
//  - automatically: StandingHeightDetector watches the head samples from the start of a session
//    and reports the standing head height once the head has held still (or, failing that, a
//    fallback estimate after a few seconds).
// The daemon's auto calibration and bodyd-eval --body-scale both run StandingHeightDetector then
// calibrate_from_head_height(), so the evaluation measures what the daemon does.
#pragma once

#include "bodyd/inference/reconstructor.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace bodyd {

// Applies a measured standing head height (metres: the Head joint's height above the floor,
// y = 0) to `reconstructor`. Returns an empty string on success; otherwise what is wrong and
// what to do (a height outside limits::kMinHeadHeightM..kMaxHeadHeightM), and the reconstructor
// is left unchanged. set_head_height_m() resets the reconstructor's history.
[[nodiscard]] std::string calibrate_from_head_height(Reconstructor& reconstructor, double head_height_m);

struct StandingHeightOptions;
// The standing head height (reconstructor's sense) of a head measured at `measured_m` while
// the user stands: measured_m / options.stance_ratio.
[[nodiscard]] double standing_height_from_head(double measured_m, const StandingHeightOptions& options);

struct StandingHeightOptions {
  // "Still": a stretch of `still_s` seconds in which the head's height varies by at most
  // `max_height_range_m` and its floor position by at most `max_floor_travel_m` (from the
  // stretch's first sample), with every sample at least `min_height_m` high. Chosen on the
  // held-out training clips (training/heldout.txt; docs/evaluation.md, "Calibration"): every clip
  // that starts standing passes within its first half second, at body scales 0.8 to 1.2, and no
  // walking, running or crouching start does.
  double still_s = 0.5;
  double max_height_range_m = 0.03;
  double max_floor_travel_m = 0.15;  // 0.3 m/s over half a second: sway passes, a slow walk does not
  double min_height_m = 0.9;         // a still head lower than this is not standing (sitting, crouching)
  // Without a still stretch by `fallback_after_s` (seconds after the first valid head sample),
  // the height is the `fallback_percentile` of the head's heights so far (a walking head bobs
  // up to about its standing height); 0 turns the fallback off. Reported as such.
  double fallback_after_s = 1.5;
  double fallback_percentile = 90.0;
  // A still head in a relaxed stance is this fraction of the reference standing pose's head
  // height (ik.h, standing_reference), the "standing head height" the reconstructors scale by:
  // 0.987 measured on the held-out training clips (the median over their still starts). The
  // reported height is the measured one divided by this.
  double stance_ratio = 0.987;
};
// Empty when usable, otherwise what is wrong (names the field).
[[nodiscard]] std::string validate(const StandingHeightOptions& options);

// What StandingHeightDetector found.
struct StandingHeight {
  double head_height_m = 0.0;      // standing head height to calibrate with (stance_ratio applied)
  double measured_m = 0.0;         // the head's height as measured (mean of the still stretch, or
                                   // the fallback percentile)
  bool fallback = false;           // no still stretch: the fallback percentile
  std::int64_t t_ns = 0;           // the sample that completed it
};

// Finds the first still stretch of the head (from the first valid head sample on) and reports the
// standing head height from it, or the fallback estimate. Pure: times come from the samples.
// Buffers are allocated in the constructor; push() does not allocate. Not thread-safe: one thread
// drives one object.
class StandingHeightDetector {
 public:
  explicit StandingHeightDetector(const StandingHeightOptions& options = {});

  // Feeds a sample (other roles, invalid and non-finite samples, and samples not later than the
  // previous head sample are ignored). Returns the result exactly once: at the sample completing
  // the first still stretch, or at the first sample `fallback_after_s` after the first one.
  [[nodiscard]] std::optional<StandingHeight> push(const TrackerSample& sample);
  // Whether the detector has reported (or given up: fallback off, or no plausible height).
  [[nodiscard]] bool done() const { return done_; }
  [[nodiscard]] const std::optional<StandingHeight>& result() const { return result_; }
  // Starts over (a new session).
  void reset();

 private:
  struct Entry {
    std::int64_t t_ns;
    Vec3 p;
  };
  [[nodiscard]] bool window_still(std::int64_t t_ns) const;
  [[nodiscard]] double fallback_height() const;

  StandingHeightOptions options_;
  bool started_ = false, done_ = false;
  std::int64_t first_t_ns_ = 0;
  std::vector<Entry> ring_;              // recent head samples, at least kMinSpacingNs apart
  std::size_t ring_head_ = 0, ring_count_ = 0;
  std::vector<std::uint32_t> histogram_;  // head heights, 1 mm bins from 0 (fallback)
  std::uint64_t histogram_count_ = 0;
  std::optional<StandingHeight> result_;
};

}  // namespace bodyd

// ------------------------------------------------------------------ calibration pose
// `bodyd-ctl calibrate --pose` (docs/control.md, docs/vr-apps.md): the user stands straight,
// looks ahead, arms relaxed at the sides, for one second. From that still second the
// PoseCalibrator estimates each device's mounting T_device_joint (motion/mounting.h) and the
// standing head height:
//  - the headset's pitch on the head (and its roll with `estimate_head_roll`): the Head joint is
//    taken to sit as the body reference's upright head looking ahead, turned to the headset's
//    heading;
//  - each controller's grip rotation: the wrist is taken to sit as the reference's relaxed
//    wrist; the wrist offset turns with the controller (it is rotated about the grip point);
//  - the eye offset (optional, `estimate_eye_offset`): the Head joint's height from the wrists'
//    height and its depth from the wrists' (the reference's ratios); otherwise the default;
//  - the standing head height: the Head joint's height through the new mounting, with the
//    stance correction of standing_height_from_head().
//  - each body tracker's mounting (hips, chest, feet, knees, elbows; device poses): its joint is
//    taken to sit as in the reference standing pose under the measured head (BodyJointsInPose);
//    a rotation-only tracker gets its rotation only. A tracker far from its joint or on the wrong
//    side refuses the pose.
// Joint-frame samples (PoseFrame::Joint) have no mounting to learn: only the height is measured.

namespace bodyd {

// Body trackers (issue 44): where each body role's joint sits in the calibration pose, from the
// reference standing pose (ik.h, standing_reference) on the reconstructor's skeleton: its position
// from the Head joint per metre of standing head height and its rotation, both in the facing frame
// (+Z ahead, +Y up, +X the body's left). In the pose, a body tracker's mounting is
// T_device_joint = T_world_device^-1 * (this joint placed under the measured head, turned to the
// headset's heading).
struct BodyJointsInPose {
  std::array<bool, kRoleCount> known{};        // body roles whose joint the skeleton has
  std::array<Vec3, kRoleCount> from_head{};    // (joint - Head joint) / standing head height
  std::array<Quat, kRoleCount> in_facing{};
};
// Throws UserError when the skeleton lacks a joint of the standing reference.
[[nodiscard]] BodyJointsInPose body_joints_in_pose(const Skeleton& skeleton);

// A body tracker further than this from its joint in the calibration pose is not where its role
// says (another joint, or a swapped role): the pose is refused, naming it. Strapped trackers sit
// a few centimetres off the joint; a person's stance moves a foot or a knee by up to ~10 cm from
// the reference's.
inline constexpr double kMaxBodyTrackerOffsetM = 0.30;
// A left-side body tracker (left_foot, left_knee, left_elbow) more than this on the body's right
// of the headset in the pose (or a right one on the left) has the other side's role.
inline constexpr double kMaxBodyTrackerWrongSideM = 0.03;
// The certainty reported for a body tracker's measured mounting rotation: the joints' rotations
// in people's standing poses differ from the reference's by this much on average (feet turned
// out, hips turned from the head): 17.1 deg on style-held-out set A's standing starts, 7.6 on set
// B's (bodyd-eval --device-frames xr --calibration-pose 0 --trackers head,hands,hips,feet;
// docs/evaluation.md, "Body trackers' mountings"), about 12 over both.
inline constexpr double kBodyTrackerPoseSdDeg = 12.0;

struct PoseCalibrationOptions {
  double still_s = 1.0;                 // how long every tracked device must hold still
  double max_position_range_m = 0.03;   // each device's positions stay within this of their mean
  double max_rotation_range_deg = 4.0;  // and its rotations within this of their mean
  bool estimate_eye_offset = false;     // docs/evaluation.md "Device frames" says why it is off
  // The headset's roll on the head from the pose too (otherwise only its pitch; the roll keeps
  // the default). Off: on the held-out training clips a person's head roll in the pose (5.0 deg
  // spread over the takes) is larger than a headset's roll on the head, so learning it made the
  // mounting worse (headset error 5.8 against 4.4 deg, mpjpe 3.99 against 3.85 cm; docs/evaluation.md).
  bool estimate_head_roll = false;
  // The pose must be the calibration pose (device frames): each tracked hand hangs at the side
  // (its grip 0.35 to 0.8 of the head's height from the floor, within 0.45 m of the head
  // horizontally), and the measured mounting is within these of the default: the headset
  // (a user looking up or down) and each controller (a hand turned, or a controller not
  // pointing ahead). Otherwise the still second is refused (PoseCalibrator::last_refusal()).
  double max_head_change_deg = 25.0;
  double max_grip_change_deg = 50.0;
  StandingHeightOptions height;         // stance_ratio and the plausibility limits
};
[[nodiscard]] std::string validate(const PoseCalibrationOptions& options);
// The furthest role `r`'s device mounting may turn from the default in a calibration pose:
// max_head_change_deg for the headset, max_grip_change_deg for a controller. The mounting file
// (daemon/src/mounting_state.h) holds what it stores to the same limits.
[[nodiscard]] double max_mounting_change_deg(const PoseCalibrationOptions& options, Role r);

struct PoseCalibration {
  Mounting mounting;                           // the defaults where a role was not measured
  std::array<bool, kRoleCount> measured{};     // which roles' mountings come from the still second
  bool device_frames = false;                  // the head's samples were device poses
  double head_height_m = 0.0;                  // standing head height to calibrate with
  double measured_head_y_m = 0.0;              // the Head joint's mean height in the still second
  // How certain: the spread of the reference pose the estimate assumes (a person's "looking
  // ahead" and "arms relaxed" vary by this much) and the stillness measured.
  std::array<double, kRoleCount> rotation_sd_deg{};
  double eye_offset_sd_cm = 0.0;
  std::array<double, kRoleCount> motion_deg{};  // largest rotation from the mean in the window
  // Body trackers: the device's distance from where the reference pose puts its joint (the
  // refusal's measure; the mounting keeps only its vertical part).
  std::array<double, kRoleCount> offset_cm{};
  std::int64_t t_ns = 0;                        // the sample that completed the still second
};

class PoseCalibrator {
 public:
  // `body_joints`: where body trackers' joints sit in the pose (body_joints_in_pose of the
  // reconstructor's skeleton); without one (all unknown) body trackers are not measured.
  PoseCalibrator(const BodyReference& reference, const Mounting& defaults, const PoseCalibrationOptions& options = {},
                 const BodyJointsInPose& body_joints = {});
  // Feeds a sample as the device sent it (before any mounting). Returns the result once: at the
  // sample that completes a still second of the head and of every hand that is tracked in it.
  [[nodiscard]] std::optional<PoseCalibration> push(const TrackerSample& sample);
  void reset();
  [[nodiscard]] bool done() const { return done_; }
  // Why the last still second was not the calibration pose (empty when none was refused).
  [[nodiscard]] const std::string& last_refusal() const { return refusal_; }
  // The last refusal was clear: a hand, a controller or the headset beyond its limit by a margin
  // (kClearHandHeightRatio, kClearHandDistanceM, kClearTurnDeg), not a near miss that the next
  // still second may pass. The daemon refuses such a pose at once instead of at its timeout.
  [[nodiscard]] bool last_refusal_clear() const { return !refusal_.empty() && refusal_clear_; }
  static constexpr double kClearHandHeightRatio = 0.05;  // of the headset's height, beyond 0.35 ... 0.8
  static constexpr double kClearHandDistanceM = 0.10;    // beyond 0.45 m from the headset
  static constexpr double kClearTurnDeg = 10.0;          // beyond max_grip_change_deg / max_head_change_deg

 private:
  [[nodiscard]] std::optional<PoseCalibration> try_estimate(std::int64_t t_ns) const;
  [[nodiscard]] std::string pose_problem(const PoseCalibration& c, const std::array<Vec3, kRoleCount>& device_p) const;

  BodyReference reference_;
  Mounting defaults_;
  PoseCalibrationOptions options_;
  BodyJointsInPose body_joints_;
  std::array<std::vector<TrackerSample>, kRoleCount> window_;  // valid samples of the last still_s
  std::array<std::int64_t, kRoleCount> last_invalid_ns_{};      // newest invalid sample per role
  std::array<bool, kRoleCount> any_invalid_{};
  bool done_ = false;
  mutable std::string refusal_;
  mutable bool refusal_clear_ = false;
};

}  // namespace bodyd
