#include "calibration_pose_wait.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace bodyd::daemon {

CalibrationPoseWait::CalibrationPoseWait(const BodyReference& reference, const Mounting& defaults,
                                         std::int64_t start_ns, double timeout_s, const BodyJointsInPose& body_joints)
    : calibrator_(reference, defaults, PoseCalibrationOptions{}, body_joints),
      start_ns_(start_ns),
      deadline_ns_(start_ns + static_cast<std::int64_t>(std::llround(timeout_s * 1e9))),
      timeout_s_(timeout_s),
      last_tracked_head_ns_(start_ns) {
  // The headset was tracking when the wait began (a valid head sample within 2 s).
  last_arrival_ns_[0] = start_ns;
  last_valid_[0] = true;
}

std::optional<CalibrationPoseWait::Outcome> CalibrationPoseWait::push(const TrackerSample& raw,
                                                                      std::int64_t arrival_ns) {
  const auto r = static_cast<std::size_t>(raw.role);
  last_arrival_ns_[r] = std::max(last_arrival_ns_[r], arrival_ns);
  last_valid_[r] = raw.valid;
  if (raw.role == Role::Head && raw.valid) last_tracked_head_ns_ = std::max(last_tracked_head_ns_, arrival_ns);
  if (std::optional<PoseCalibration> c = calibrator_.push(raw)) return Outcome{std::move(c), {}};
  // A whole still second held clearly out of the pose: the user is holding still where they think
  // the pose is, and waiting longer only delays the answer.
  if (raw.role == Role::Head && calibrator_.last_refusal_clear())
    return Outcome{std::nullopt, "not the calibration pose: " + calibrator_.last_refusal() + "; then retry"};
  return std::nullopt;
}

std::string CalibrationPoseWait::stopped_at(std::int64_t last_ns) const {
  return fmt::format("tracking stopped at {:.1f} s: ",
                     static_cast<double>(std::max<std::int64_t>(last_ns - start_ns_, 0)) * 1e-9);
}

std::optional<CalibrationPoseWait::Outcome> CalibrationPoseWait::tick(std::int64_t now_ns, bool caught_up) {
  if (caught_up) {
    if (now_ns - last_arrival_ns_[0] > kStoppedNs)
      return Outcome{std::nullopt,
                     stopped_at(last_arrival_ns_[0]) +
                         "the headset's samples stopped (none for 0.5 s): is the headset on and tracking, "
                         "and its app (VRChat, SteamVR, WiVRn) running? Then retry"};
    if (now_ns - last_tracked_head_ns_ > kStoppedNs)
      return Outcome{std::nullopt, stopped_at(last_tracked_head_ns_) +
                                       "the headset lost tracking (its samples say it is not tracked, for 0.5 s): "
                                       "is the play space lit and in view? Then retry"};
    // A controller or body tracker whose newest sample was tracked and then stopped holds the
    // still second up for ever (the calibrator waits for its second to complete). One that
    // reported itself lost is left out of the calibration instead, as before.
    for (Role r : kRoles) {
      const auto h = static_cast<std::size_t>(r);
      if (r == Role::Head) continue;
      if (last_arrival_ns_[h] != 0 && last_valid_[h] && now_ns - last_arrival_ns_[h] > kStoppedNs)
        return Outcome{std::nullopt, stopped_at(last_arrival_ns_[h]) +
                                         fmt::format("the {} {}'s samples stopped (none for 0.5 s): is it "
                                                     "switched on and tracking? Then retry",
                                                     role_name(r), is_xr_role(r) ? "controller" : "tracker")};
    }
  }
  if (now_ns <= deadline_ns_) return std::nullopt;
  const std::string& refusal = calibrator_.last_refusal();
  if (!refusal.empty()) return Outcome{std::nullopt, "not the calibration pose: " + refusal + "; then retry"};
  return Outcome{std::nullopt,
                 fmt::format("no still second (the headset and every tracked controller held still for 1 s) "
                             "in {:g} s: stand straight, look ahead, let the arms hang relaxed at the "
                             "sides, hold still and retry",
                             timeout_s_)};
}

}  // namespace bodyd::daemon
