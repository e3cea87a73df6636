// The body pipeline: what every tracker sample goes through on its way to the reconstructor, the
// daemon's and bodyd-eval's alike (issue 45 item 2: one copy, so what the evaluation measures is
// what the daemon publishes): the sample conditioning (sample_conditioning.h) and the three
// calibrations around it (calibration.h), in this order:
//   1. the raw sample (as the device sent it, before any mounting) to the calibration pose held
//      from the stream's start, if one is (bodyd-eval --calibration-pose; the daemon's, asked for
//      on the control socket, waits in daemon/src/calibration_pose_wait.h and is applied with
//      apply_calibration_pose()), then to the auto calibration's still second;
//   2. the conditioning: a body tracker's device pose before its mounting is measured is not used;
//      the mounting, the offset, the re-centring; the rotation made unit length;
//   3. the auto height calibration: the conditioned head sample to a StandingHeightDetector, and
//      the height it reports applied before the sample is pushed, so the sample counts at the new
//      size;
//   4. the push to the reconstructor.
// What the calibrations applied comes back as plain events: the caller logs, shows and keeps them
// (the daemon: its log, status, recording and mounting file; bodyd-eval: its report). push() runs
// the four steps; the daemon runs them one by one (observe_raw, conditioner(), before_push) for
// what it does between them (statistics, status, the recording of the conditioned sample).
//
// The reconstructor is a parameter, not owned: the daemon swaps it on a model reload. One thread
// drives one object.
#pragma once

#include "bodyd/inference/calibration.h"
#include "bodyd/inference/reconstructor.h"
#include "bodyd/inference/sample_conditioning.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string>

namespace bodyd {

// What the auto height calibration did: once, then it stops.
struct AutoHeightEvent {
  enum class Outcome {
    Applied,   // `height` is the reconstructor's now (its history was reset)
    Refused,   // calibrate_from_head_height() refused `height`: `error` says why
    NotFound,  // no plausible standing height (sitting? the detector gave up)
  };
  Outcome outcome = Outcome::NotFound;
  StandingHeight height;
  std::string error;
};

// What the auto calibration's still second applied: the first still second of the session that
// passes the calibration pose's checks measures the body trackers whose mountings are not measured
// yet, and refines the headset's mounting (its pitch) when it is plausible. Device frames only: a
// still second of joint poses applies nothing.
struct StillSecondEvent {
  PoseCalibration calibration;                   // what the still second measured
  std::array<bool, kRoleCount> body_measured{};  // body trackers whose mountings it set (then the reconstructor was reset)
  Mounting mounting_after_body;                  // the mounting once they were set, before the headset's
  enum class Head {
    Kept,     // not refined: joint frames, its mounting measured already, or not asked to
    Refined,  // the headset's mounting is the still second's
    TooFar,   // the still second's is over kMaxStillHeadChangeDeg from the default (looking up or down?)
  };
  Head head = Head::Kept;
  double head_change_deg = 0.0;  // Refined, TooFar: the still second's headset mounting from the default
};

// What a calibration pose applied (apply_calibration_pose).
struct CalibrationPoseEvent {
  PoseCalibration calibration;
  std::string height_error;  // empty: the height was applied (or not asked for)
};

// What one raw sample set off (step 1).
struct RawSampleEvents {
  std::optional<CalibrationPoseEvent> calibration_pose;  // the held calibration pose, found and applied
  std::optional<StillSecondEvent> still_second;
  // The still second's window passed without one: it stopped (the headset's default mounting
  // stays; body trackers not measured yet stay unused).
  bool still_second_expired = false;
};

// What push() did with a sample.
struct SampleEvents {
  RawSampleEvents raw;
  bool used = true;  // false: a body tracker's device pose whose mounting is not measured (not pushed)
  std::optional<AutoHeightEvent> height;
};

class BodyPipeline {
 public:
  // The still second refines the headset's mounting only within this of the default: a user
  // who stands still looking down at a menu must not get a bent body.
  static constexpr double kMaxStillHeadChangeDeg = 15.0;
  // The still second is looked for only at the start of a session, this long from the first
  // valid head sample (arrival time: the host's in the daemon, as a replay's time base may loop):
  // a still second later may be a user looking at a menu.
  static constexpr std::int64_t kStillSecondWindowNs = 10'000'000'000;

  explicit BodyPipeline(const SampleConditioner::Offsets& offsets = {}) : conditioner_(offsets) {}

  // Step 2's conditioner: its default mounting and the mountings known before the first sample
  // (the mounting file, an oracle) are set on it; the re-centring too.
  [[nodiscard]] SampleConditioner& conditioner() { return conditioner_; }
  [[nodiscard]] const SampleConditioner& conditioner() const { return conditioner_; }

  // ---------------------------------------------------------------- the calibrations
  // Step 3, the auto height calibration (the daemon's auto_calibrate without a known height;
  // bodyd-eval --body-scale): runs from the next head sample until it reports once.
  void start_auto_height(const StandingHeightOptions& options = {});
  // A height from elsewhere (the control socket) supersedes it: it stops.
  void stop_auto_height() { height_detector_.reset(); }
  [[nodiscard]] bool auto_height_running() const { return height_detector_.has_value(); }

  // Step 1, the auto calibration's still second (StillSecondEvent), for kStillSecondWindowNs.
  // `refine_head`: it may refine the headset's mounting (the daemon: with the auto height
  // calibration, while the headset's mounting is the default). Starts only when it has something
  // to do: the headset to refine, or a body tracker's mounting not measured yet.
  void start_still_second(const BodyReference& reference, const Mounting& defaults, const BodyJointsInPose& body_joints,
                          bool refine_head, const PoseCalibrationOptions& options = {});
  [[nodiscard]] bool still_second_running() const { return still_.has_value(); }
  [[nodiscard]] bool still_second_refines_head() const { return refine_head_; }

  // Step 1, a calibration pose held from the stream's start (bodyd-eval --calibration-pose: a
  // user who stands in it when the session starts): `calibrator` gets every raw sample until it
  // finds the pose, which is then applied (apply_calibration_pose, the height only with
  // `apply_height`).
  void hold_calibration_pose(PoseCalibrator calibrator, bool apply_height);

  // Applies a calibration pose's result: every measured role's mounting, a fresh history for the
  // reconstructor (the inputs jumped) and, with `apply_height`, its standing head height. A height
  // applied supersedes the auto calibrations: the auto height and the still second stop.
  CalibrationPoseEvent apply_calibration_pose(const PoseCalibration& c, Reconstructor& reconstructor, bool apply_height = true);

  // ---------------------------------------------------------------- per sample
  // Steps 1 to 4 on one sample; `arrival_ns` is when it arrived (host time in the daemon; the
  // sample's time in bodyd-eval).
  SampleEvents push(TrackerSample sample, std::int64_t arrival_ns, Reconstructor& reconstructor);

  // The steps one by one. Step 1: the raw sample.
  RawSampleEvents observe_raw(const TrackerSample& raw, std::int64_t arrival_ns, Reconstructor& reconstructor);
  // Step 2 is conditioner(): uses(), condition(), SampleConditioner::finish().
  // Step 3: the conditioned sample, before it is pushed; the auto height's outcome, once.
  std::optional<AutoHeightEvent> before_push(const TrackerSample& s, Reconstructor& reconstructor);
  // The samples' time base started over (a replay looped, a source restarted): the auto height
  // calibration, if running, starts over too (its times went back).
  void time_restarted();

 private:
  StillSecondEvent apply_still_second(const PoseCalibration& c, Reconstructor& reconstructor);

  SampleConditioner conditioner_;
  std::optional<StandingHeightDetector> height_detector_;
  // The still second: its calibrator, the default it refines the headset from, and when its
  // window started (INT64_MIN: no valid head sample yet).
  std::optional<PoseCalibrator> still_;
  Mounting still_defaults_;
  bool refine_head_ = false;
  std::int64_t still_first_ns_ = INT64_MIN;
  std::optional<PoseCalibrator> held_pose_;
  bool held_pose_height_ = false;
};

}  // namespace bodyd
