// Sample conditioning: what every tracker sample goes through between its source and the
// reconstructor (docs/daemon.md "Device mounting", docs/control.md "reset"), in this order:
//   1. a device pose (PoseFrame::Device) becomes a joint pose through its role's mounting;
//   2. the role's device offset (config "offsets"), if any;
//   3. the re-centring, once a `reset` asked for one;
//   4. (--record-trackers records the sample here, tracker_recorder.h)
//   5. the rotation made unit length (unit_rotation, tracker_log.h) - always, so the
//      reconstructor's input does not depend on whether a recording is made, and a replay of a
//      recording reaches the reconstructor bit-identical (the log reader ends with it too).
// And the one cache of the latest valid head sample (LatestHead) that the control commands read.
// Reconstruction thread only.
#pragma once

#include "bodyd/inference/reconstructor.h"

#include "bodyd/daemon/config.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/tracker.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <optional>

namespace bodyd::daemon {

// What a re-centring did: the head's heading turned to forward and its floor position moved to
// the origin (both before the turn).
struct Recentring {
  double heading_deg = 0.0;
  Vec3 origin_m = Vec3::Zero();  // (x, 0, z)
};

class SampleConditioner {
 public:
  explicit SampleConditioner(const std::array<std::optional<DeviceOffset>, kRoleCount>& offsets) : offsets_(offsets) {}

  // Steps 1-3 (above) on `s`: what --record-trackers records.
  void condition(TrackerSample& s);
  // Step 5: the rotation made unit length (valid samples).
  static void finish(TrackerSample& s);

  // The mounting of step 1 (calibration sets it; daemon.cpp).
  [[nodiscard]] const Mounting& mounting() const { return mounting_; }
  void set_mounting(Role role, const RigidTransform& T_device_joint) {
    mounting_.T_device_joint[static_cast<int>(role)] = T_device_joint;
  }
  void set_mounting(const Mounting& m) { mounting_ = m; }
  // Whether a device-frame sample of the role has arrived.
  [[nodiscard]] bool device_frames_seen(Role role) const { return device_frames_seen_[static_cast<int>(role)]; }

  // Re-centring ("reset", docs/control.md): every sample, after its device offset, becomes
  // T_recentre * sample with T_recentre(p) = rotation * p + translation_m (a turn about +Y and
  // a move on the floor). recentre_on makes the head's heading and floor position (the model's
  // canonical frame, features.h) forward (+Z) and the origin: T_new = C * T_old with
  // C(p) = R_canon_world * (p - origin). `head` (already conditioned) is moved by C too.
  Recentring recentre_on(TrackerSample& head);
  [[nodiscard]] bool recentred() const { return recentred_; }
  // The total re-centring (identity until a reset).
  [[nodiscard]] Quat recentre_rotation() const { return recentred_ ? recentre_rotation_ : Quat::Identity(); }
  [[nodiscard]] Vec3 recentre_translation_m() const { return recentred_ ? recentre_translation_m_ : Vec3::Zero(); }
  // status's keys: {"recentred": bool} and, after a reset, "recentre": {heading_deg, origin_m [x, z]}.
  [[nodiscard]] nlohmann::json recentre_status() const;
  // `body` (the reconstruction, in the user's re-centred space) in the space the samples came in
  // (OutputSpace::Runtime, output.h): the one place the re-centring is undone. Its global poses
  // and its root's local transform; the rest is copied. Allocates only when out's sizes differ.
  void to_runtime_space(const BodyPose& body, BodyPose& out) const;

 private:
  std::array<std::optional<DeviceOffset>, kRoleCount> offsets_;
  Mounting mounting_;
  std::array<bool, kRoleCount> device_frames_seen_{};
  Quat recentre_rotation_ = Quat::Identity();
  Vec3 recentre_translation_m_ = Vec3::Zero();
  bool recentred_ = false;
};

// The latest valid head sample as the reconstructor got it, when it arrived (host monotonic
// time) and the head's speed: the one cache of it, with one freshness rule.
class LatestHead {
 public:
  // A sample newer than this is fresh enough for a command that needs the head now
  // (calibrate --from-head, --pose, reset).
  static constexpr std::int64_t kFreshNs = 2'000'000'000;

  // A valid head sample (conditioned) arrived.
  void update(const TrackerSample& s, std::int64_t arrival_ns);
  // A valid head sample arrived within kFreshNs of now_ns.
  [[nodiscard]] bool fresh(std::int64_t now_ns) const { return arrival_ns_ != 0 && now_ns - arrival_ns_ <= kFreshNs; }
  [[nodiscard]] const TrackerSample& sample() const { return sample_; }
  [[nodiscard]] TrackerSample& sample() { return sample_; }  // re-centring moves it
  // Its speed, smoothed over about 0.2 s (calibrate --from-head refuses a walking head).
  [[nodiscard]] double speed_m_s() const { return speed_m_s_; }

 private:
  TrackerSample sample_;
  std::int64_t arrival_ns_ = 0;
  double speed_m_s_ = 0.0;
};

}  // namespace bodyd::daemon
