// The wait of a calibration pose (calibrate "from": "pose", docs/control.md): the raw samples go
// to a PoseCalibrator until it finds the still second, and the wait ends as soon as its outcome
// is certain, saying why: a still second that is clearly not the pose, a device whose samples
// stopped, or the timeout. Reconstruction thread; time is a parameter (host monotonic ns: the
// samples' arrival and the loop's clock), so tests drive it with made-up times.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "bodyd/inference/calibration.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/tracker.h"

namespace bodyd::daemon {

class CalibrationPoseWait {
 public:
  // A device that has sent nothing (or the headset nothing tracked) for this long has stopped:
  // a still second cannot include it, so the wait ends instead of running to its timeout.
  // Headsets and controllers send 60 to 120 samples a second (bridges at most 100).
  static constexpr std::int64_t kStoppedNs = 500'000'000;

  // How the wait ended: a calibration, or a refusal saying what to change (without the
  // "calibrate from pose: " prefix).
  struct Outcome {
    std::optional<PoseCalibration> calibration;
    std::string refusal;
  };

  // Starts at `start_ns`, when the headset was tracking (the daemon checks that first).
  // `body_joints`: where body trackers' joints sit in the pose (PoseCalibrator).
  CalibrationPoseWait(const BodyReference& reference, const Mounting& defaults, std::int64_t start_ns,
                      double timeout_s, const BodyJointsInPose& body_joints = {});

  // A sample as the device sent it (before any mounting) and when it arrived. The outcome when it
  // completes the still second, or ends a still second that is clearly not the pose.
  [[nodiscard]] std::optional<Outcome> push(const TrackerSample& raw, std::int64_t arrival_ns);
  // The outcome when a device stopped or the time is up. `caught_up`: every sample that arrived
  // before now_ns was pushed (otherwise a backlog would look like a device that stopped).
  [[nodiscard]] std::optional<Outcome> tick(std::int64_t now_ns, bool caught_up);

 private:
  [[nodiscard]] std::string stopped_at(std::int64_t last_ns) const;

  PoseCalibrator calibrator_;
  std::int64_t start_ns_;
  std::int64_t deadline_ns_;
  double timeout_s_;
  std::array<std::int64_t, kRoleCount> last_arrival_ns_{};  // each role's newest sample (0: none yet)
  std::array<bool, kRoleCount> last_valid_{};               // and whether it was tracked
  std::int64_t last_tracked_head_ns_;                       // the newest tracked head sample
};

}  // namespace bodyd::daemon
