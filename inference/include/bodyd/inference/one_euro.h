// The One Euro filter (Casiez, Roussel, Vogel, "1€ Filter: A Simple Speed-based Low-pass Filter
// for Noisy Input in Interactive Systems", CHI 2012), per tracker: an exponential low-pass whose
// cutoff rises with speed, so a still tracker is steady (low cutoff: noise removed) and a fast one
// is followed closely (high cutoff: little lag). Here it smooths the tracker samples the diffusion
// model sees (docs/model.md, "Tracker filter"); the tracked joints are still placed on the raw
// samples (body_solver.h).
//
// Position: cutoff_hz = min_cutoff_hz + beta_per_m_s * |v|, v the velocity low-passed at
// d_cutoff_hz; each step x = x_pred + a (x_in - x_pred) with a = 1 / (1 + 1 / (2 pi cutoff dt))
// and x_pred = x_prev + v dt (predict_velocity; the paper's filter has x_pred = x_prev and lags
// a steady motion by speed / (2 pi cutoff)).
// Rotation: the same with the angular velocity (rad/s), by slerp from the previous output.
// Time steps come from the samples' timestamps; a tracker that was invalid or silent for more
// than `restart_after_s` starts over at its next valid sample (no smoothing across a gap).
//
// Noise gate: any low-pass lags, and a lag of millimetres on a clean tracker puts the tracked
// joints off their trackers and shakes the body as the lag changes with speed. So the filter
// measures each tracker's noise and filters only as much as it finds: the noise level is taken
// from the third differences of the samples (for white noise of sigma per axis, E|D3|^2 =
// 60 sigma^2 whatever the rate; human motion adds jerk * dt^3, small at tracker rates) as a low
// quantile over the last `noise_window` samples (robust to bursts of motion), and the output is
// raw + g * (filtered - raw) with the gain g rising from 0 at `noise_gate_low_mm` to 1 at
// `noise_gate_high_mm` (rotations likewise, in degrees). A clean tracker (e.g. a headset with
// sub-millimetre noise) passes unchanged; a noisy one gets the full filter. The noise
// measurement survives gaps and starts over only at reset().
// Without the gate (noise_gate false) the full filter always applies: the body filter below.
//
// PoseFilter: the same filter on a body pose (the diffusion reconstructor's output-side body
// filter, diffusion.h, docs/model.md "Body filter"): one OneEuroFilter per joint on its local
// rotation, and on the local translation of one joint (the Hips: the body's position), without
// the noise gate, so a constant pose passes unchanged and a jittery one is smoothed.
// Pure, no allocation (PoseFilter allocates in its constructor only); not thread-safe (one
// thread drives one object).
#pragma once

#include "bodyd/motion/skeleton.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <utility>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd {

struct OneEuroOptions {
  bool enabled = true;
  double min_cutoff_hz = 1.0;        // position cutoff of a still tracker
  double beta_per_m_s = 5.0;         // cutoff increase per m/s of speed
  double rot_min_cutoff_hz = 1.0;    // rotation cutoff of a still tracker
  double rot_beta_per_rad_s = 2.0;   // cutoff increase per rad/s of angular speed
  double d_cutoff_hz = 1.0;          // cutoff of the speed estimate
  double restart_after_s = 0.25;     // a gap longer than this restarts the filter
  // Predict each step with the filtered velocity (x += v dt before the low-pass): a tracker
  // moving steadily is followed without lag, so the cutoff can stay low (less noise) at speed.
  bool predict_velocity = true;
  // Noise gate (see above): no filtering below the low level, the full filter from the high one.
  double noise_gate_low_mm = 1.25;   // measured position noise (sigma per axis)
  double noise_gate_high_mm = 1.75;
  double rot_noise_gate_low_deg = 0.5;   // measured rotation noise (sigma per axis)
  double rot_noise_gate_high_deg = 0.8;
  int noise_window = 64;             // samples the noise is measured over (16..kMaxNoiseWindow)
  // false: no noise measurement, the full filter always (gain 1; PoseFilter's setting).
  bool noise_gate = true;
  // Head correction (the diffusion reconstructor, diffusion.h; docs/model.md "Tracked joints"):
  // on a noisy head tracker the Head joint goes to the network's head plus the low-passed
  // difference between the filtered tracker and the network's head (this cutoff, Hz), weighted
  // by the head filter's noise-gate gain: a clean head stays exactly on its tracker. Chosen on the
  // style-held-out clips (docs/models.md, "Tracker noise on unseen styles").
  double head_correction_cutoff_hz = 4.0;
  // Soft reach of the arms on a noisy hand tracker (metres, >= 0; 0: off): near a straight arm the
  // two-bone IK turns millimetres of hand noise into centimetres of elbow motion, so within this
  // distance of full reach the arm's reach approaches full length smoothly (two_bone_ik.h,
  // TwoBoneTarget::soft_zone_m), the zone scaled by the hand filter's noise-gate gain: a clean
  // hand is reached exactly.
  double arm_soft_zone_m = 0.01;
  // Smoothed anchor on a noisy head tracker (Hz, >= 0; 0: off). Each window is expressed in the
  // frame of its newest head (docs/model.md, "Canonical frame"), so a noisy head moves that frame
  // and the whole body with it. With this cutoff the frame's origin and heading come from the
  // head low-passed at it (a One Euro filter like the head correction's), weighted by the head
  // filter's noise-gate gain: with a clean head the frame is the head's own, as in training.
  double anchor_cutoff_hz = 0.5;
  // Reach slack on a noisy hand tracker (metres, >= 0; 0: off). The body is moved so that each
  // shoulder stays within reach of its hand (body_solver.h, TrackedTargets::hand_slack_m); a noisy
  // hand near full reach crossed that limit frame by frame and pulled the whole body with its
  // noise. With slack the body chases only a hand further than this beyond full reach; within
  // it the arm stretches as far as it goes (arm_soft_zone_m) and the hand falls short of its
  // tracker by at most the slack. Scaled by the hand filter's noise-gate gain: a clean hand is
  // reached exactly as before.
  double hand_reach_slack_m = 0.06;
  // anchor_cutoff_hz, hand_reach_slack_m and arm_soft_zone_m were chosen together on the
  // style-held-out clips (docs/models.md, "The smoothed anchor, the reach slack and the soft arms").
};
inline constexpr int kMaxNoiseWindow = 256;
inline constexpr int kNoiseOrder = 6;  // the order of the differences the noise is measured by
// Empty when usable, otherwise what is wrong (names the field, after `group`: "filter min_cutoff_hz
// must be > 0, not 0").
[[nodiscard]] std::string validate(const OneEuroOptions& options, std::string_view group = "filter");

// The output-side body filter (PoseFilter; the daemon's "body_filter" keys, docs/daemon.md "Body
// filter"). The same cutoffs as OneEuroOptions: position (the Hips) cutoff_hz = min_cutoff_hz +
// beta_per_m_s * speed, rotation (every joint's local rotation) rot_min_cutoff_hz +
// rot_beta_per_rad_s * angular speed. Off by default (the defaults are to be chosen on held-out
// styles, docs/evaluation.md).
// The defaults were chosen on the style-held-out clips (docs/models.md, "Post-processing chosen on
// unseen styles").
struct BodyFilterOptions {
  bool enabled = true;
  double min_cutoff_hz = 10.0;      // Hips position cutoff of a still body, Hz
  double beta_per_m_s = 1.0;        // its increase per m/s of Hips speed
  double d_cutoff_hz = 1.0;         // cutoff of the speed estimates, Hz
  double rot_min_cutoff_hz = 10.0;  // joint rotation cutoff of a still joint, Hz
  double rot_beta_per_rad_s = 0.5;  // its increase per rad/s of the joint's angular speed
};
// The OneEuroOptions PoseFilter runs with: these cutoffs, no noise gate, the other fields at
// OneEuroOptions' defaults.
[[nodiscard]] OneEuroOptions one_euro_options(const BodyFilterOptions& options);
// Empty when usable, otherwise what is wrong ("body_filter min_cutoff_hz must be > 0, not 0").
[[nodiscard]] std::string validate(const BodyFilterOptions& options);

// One tracker's filter.
class OneEuroFilter {
 public:
  explicit OneEuroFilter(const OneEuroOptions& options = {}) : options_(options) {}
  // The filtered sample (time, role and validity unchanged). Invalid samples pass unchanged and
  // mark a gap; samples not later than the previous one pass unchanged.
  [[nodiscard]] TrackerSample filter(const TrackerSample& in);
  void reset() {
    started_ = false;
    recent_count_ = noise_count_ = noise_next_ = 0;
    position_gain_ = rotation_gain_ = 0.0;
  }
  // The measured noise (sigma per axis; 0 until noise_window / 4 differences are in) and the
  // gains of the noise gate now.
  [[nodiscard]] double position_noise_mm() const { return position_noise_mm_; }
  [[nodiscard]] double rotation_noise_deg() const { return rotation_noise_deg_; }
  [[nodiscard]] double position_gain() const { return position_gain_; }
  [[nodiscard]] double rotation_gain() const { return rotation_gain_; }

 private:
  void measure_noise(const TrackerSample& in);

  OneEuroOptions options_;
  bool started_ = false;
  bool first_step_ = false;  // the next sample is the first after a (re)start
  std::int64_t last_t_ns_ = 0;
  Vec3 x_ = Vec3::Zero(), dx_ = Vec3::Zero();  // filtered position, filtered velocity (m/s)
  Quat q_ = Quat::Identity();
  Vec3 w_ = Vec3::Zero();                      // filtered angular velocity (rad/s, world)
  // Noise measurement: the last valid samples of an uninterrupted stretch (oldest first) and a
  // ring of squared third differences (position m^2, rotation rad^2).
  std::array<TrackerSample, kNoiseOrder + 1> recent_{};
  int recent_count_ = 0;
  std::array<double, kMaxNoiseWindow> d3_position_{}, d3_rotation_{}, scratch_{};
  int noise_count_ = 0, noise_next_ = 0;
  double position_noise_mm_ = 0.0, rotation_noise_deg_ = 0.0;
  double position_gain_ = 0.0, rotation_gain_ = 0.0;
};

// The filters of the tracker roles, one per role, all with the same options.
class TrackerFilter {
 public:
  explicit TrackerFilter(const OneEuroOptions& options = {})
      : filters_(filled(options, std::make_index_sequence<kRoleCount>{})), enabled_(options.enabled) {}
  [[nodiscard]] TrackerSample filter(const TrackerSample& in) {
    return enabled_ ? filters_[static_cast<size_t>(in.role)].filter(in) : in;
  }
  void reset() {
    for (OneEuroFilter& f : filters_) f.reset();
  }
  [[nodiscard]] const OneEuroFilter& of(Role role) const { return filters_[static_cast<size_t>(role)]; }

 private:
  template <std::size_t... I>
  static std::array<OneEuroFilter, kRoleCount> filled(const OneEuroOptions& options, std::index_sequence<I...>) {
    return {((void)I, OneEuroFilter(options))...};
  }

  std::array<OneEuroFilter, kRoleCount> filters_;
  bool enabled_ = true;
};

// The body filter (see the top): one filter per joint of a skeleton.
class PoseFilter {
 public:
  PoseFilter() = default;
  // For poses of `joint_count` joints; `translated_joint`'s local translation is filtered too
  // (-1: none). Disabled options make filter() a no-op.
  PoseFilter(const BodyFilterOptions& options, int joint_count, int translated_joint);
  // Filters `pose` (local rotations, and the translated joint's translation) in place as the
  // sample at t_ns; a time not later than the previous one passes unchanged, and a gap longer
  // than restart_after_s (0.25 s) starts over. `pose` must have joint_count joints.
  void filter(std::int64_t t_ns, Pose& pose);
  void reset() {
    for (OneEuroFilter& f : filters_) f.reset();
  }
  [[nodiscard]] bool enabled() const { return enabled_; }

 private:
  std::vector<OneEuroFilter> filters_;
  int translated_joint_ = -1;
  bool enabled_ = false;
};

}  // namespace bodyd
