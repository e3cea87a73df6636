// Sample conditioning: what every tracker sample goes through between its source and the
// reconstructor, the daemon's and the evaluation's alike (docs/daemon.md "Device mounting",
// docs/control.md "recenter"; issue 45 item 2: one copy, so what bodyd-eval measures is what the
// daemon publishes), in this order:
//   0. uses(): a body tracker's device pose is not used before its mounting is measured;
//   1. a device pose (PoseFrame::Device) becomes a joint pose through its role's mounting;
//   2. the role's device offset (the daemon's config "offsets"), if any;
//   3. the re-centring, once a `recenter` asked for one;
//   4. (the daemon's --record-trackers records the sample here)
//   5. finish(): the rotation made unit length (unit_rotation, tracker_log.h) - always, so the
//      reconstructor's input does not depend on whether a recording is made, and a replay of a
//      recording reaches the reconstructor bit-identical (the log reader ends with it too).
// One thread drives one object.
#pragma once

#include "bodyd/inference/reconstructor.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <optional>

namespace bodyd {

// What a re-centring did: the head's heading turned to forward and its floor position moved to
// the origin (both before the turn).
struct Recentring {
  double heading_deg = 0.0;
  Vec3 origin_m = Vec3::Zero();  // (x, 0, z)
};

class SampleConditioner {
 public:
  using Offsets = std::array<std::optional<RigidTransform>, kRoleCount>;  // T_offset per role
  explicit SampleConditioner(const Offsets& offsets = {}) : offsets_(offsets) {}

  // Step 0: false for a body tracker's device pose whose mounting is not measured (a strap sits
  // a few centimetres off the joint and turned any way: a device pose is never used through an
  // unknown offset at full weight). Joint poses, and the headset's and controllers' device
  // poses (their default mounting is derived from data), are always used.
  [[nodiscard]] bool uses(const TrackerSample& s) const {
    return is_xr_role(s.role) || s.frame != PoseFrame::Device || measured_[static_cast<int>(s.role)];
  }
  // Steps 1-3 (above) on `s`: what --record-trackers records.
  void condition(TrackerSample& s);
  // Step 5: the rotation made unit length (valid samples).
  static void finish(TrackerSample& s);

  // The mounting of step 1. The defaults (the headset's and controllers' derived mounting; the
  // body trackers' none): set_default_mounting. A measured one (a calibration pose, the auto
  // calibration, the mounting file, an oracle): set_mounting, which also lets uses() take the
  // role's device poses.
  [[nodiscard]] const Mounting& mounting() const { return mounting_; }
  void set_default_mounting(const Mounting& m) {
    mounting_ = m;
    measured_ = {};
  }
  void set_mounting(Role role, const RigidTransform& T_device_joint) {
    mounting_.T_device_joint[static_cast<int>(role)] = T_device_joint;
    measured_[static_cast<int>(role)] = true;
  }
  [[nodiscard]] bool measured(Role role) const { return measured_[static_cast<int>(role)]; }
  // Whether a device-frame sample of the role has been conditioned.
  [[nodiscard]] bool device_frames_seen(Role role) const { return device_frames_seen_[static_cast<int>(role)]; }

  // Re-centring ("recenter", docs/control.md): every sample, after its device offset, becomes
  // T_recentre * sample with T_recentre(p) = rotation * p + translation_m (a turn about +Y and
  // a move on the floor). recentre_on makes the head's heading and floor position (the model's
  // canonical frame, features.h) forward (+Z) and the origin: T_new = C * T_old with
  // C(p) = R_canon_world * (p - origin). `head` (already conditioned) is moved by C too.
  Recentring recentre_on(TrackerSample& head);
  [[nodiscard]] bool recentred() const { return recentred_; }
  // The total re-centring (identity until a recenter).
  [[nodiscard]] Quat recentre_rotation() const { return recentred_ ? recentre_rotation_ : Quat::Identity(); }
  [[nodiscard]] Vec3 recentre_translation_m() const { return recentred_ ? recentre_translation_m_ : Vec3::Zero(); }
  // `body` (the reconstruction, in the user's re-centred space) in the space the samples came in
  // (the daemon's OutputSpace::Runtime): the one place the re-centring is undone. Its global
  // poses and its root's local transform; the rest is copied. Allocates only when out's sizes differ.
  void to_runtime_space(const BodyPose& body, BodyPose& out) const;

 private:
  Offsets offsets_;
  Mounting mounting_;
  std::array<bool, kRoleCount> measured_{};
  std::array<bool, kRoleCount> device_frames_seen_{};
  Quat recentre_rotation_ = Quat::Identity();
  Vec3 recentre_translation_m_ = Vec3::Zero();
  bool recentred_ = false;
};

}  // namespace bodyd
