// Tracker simulator: the three tracker streams a headset and two controllers would
// report while a person performs a motion-capture clip (spec: docs/simulator.md).
//
// The true pose of a role at time t is the global pose of its skeleton joint (Head,
// Hand_L, Hand_R) from forward kinematics of the clip, interpolated between frames
// (positions linearly, rotations by slerp). Frame k of the clip is at t = k * frame_time,
// starting at 0, in the log's time base. On top of that the simulator models Gaussian
// position and rotation noise, a constant latency, timestamp jitter and tracking-loss
// episodes of the hands. Everything random comes from std::mt19937_64 streams seeded
// from SimOptions::seed (one stream per role and effect) with this library's own
// uniform/normal/exponential transforms, so a seed gives bit-identical output on every
// platform and changing one role's rate does not change another role's noise.
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/tracker.h"

#include <optional>

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace bodyd {

class SimError : public UserError {
 public:
  using UserError::UserError;
};

struct SimOptions {
  // Sample rate of every role, Hz; role_rate_hz[r] > 0 overrides it for role r
  // (indexed by Role: head, left_hand, right_hand).
  double rate_hz = 90.0;
  std::array<double, kRoleCount> role_rate_hz{};

  // The roles simulated (issue 44: body trackers besides the headset and controllers), each at
  // its joint (docs/conventions.md, "Tracker roles"); `rotation_only` ones carry rotations alone
  // (IMU trackers: has_position false).
  std::vector<Role> roles{kXrRoles.begin(), kXrRoles.end()};
  std::vector<Role> rotation_only;

  // White Gaussian noise per sample: position noise is N(0, s^2) on each axis (mm);
  // rotation noise is a rotation exp(w) applied in the world frame (q' = exp(w) * q)
  // with each component of w drawn from N(0, s^2) (degrees).
  double position_noise_mm = 0.0;
  double rotation_noise_deg = 0.0;

  // Each sample's timestamp = true time + latency + jitter. Jitter is N(0, jitter_ms^2)
  // clamped to less than half the role's sample period, so time still increases within
  // each role. Latency may not be negative.
  double latency_ms = 0.0;
  double jitter_ms = 0.0;

  // Tracking loss of the hands (the head is never lost): episodes start as a Poisson
  // process at `dropout_rate_hz` expected episodes per hand per second of tracked
  // time; each lasts an exponentially distributed time with mean `dropout_mean_ms`.
  // Samples whose true time falls in an episode are invalid. The expected fraction of
  // invalid hand samples is rate*mean / (1 + rate*mean) (see dropout_fraction()).
  double dropout_rate_hz = 0.0;
  double dropout_mean_ms = 300.0;

  std::uint64_t seed = 1;

  // Device frames (docs/simulator.md "Device frames"): when set, every sample is the pose a
  // device mounted with this T_device_joint per role reports (the headset at the eyes in the XR
  // axes, the controllers' grip poses; frame = PoseFrame::Device), computed from the joint's
  // true pose before noise is added. draw_session_mounting() gives a random one.
  std::optional<Mounting> device_mounting;

  // The rate of one role (the override, or rate_hz).
  [[nodiscard]] double rate_of(Role role) const;
  // Expected long-run fraction of hand samples that are invalid.
  [[nodiscard]] double dropout_fraction() const;
  // Empty when the options are usable, otherwise what is wrong (names the field).
  [[nodiscard]] std::string validate() const;
};

// How far a session's mounting strays from the default (docs/simulator.md): each drawn
// uniformly within +- the value, per session, from the seed.
struct MountingSpread {
  double eye_offset_m = 0.02;       // each axis of the head's T_device_joint position
  double head_pitch_deg = 10.0;     // the headset pitched on the head (about its +X)
  double head_roll_deg = 3.0;       // and rolled (about its -Z)
  double grip_rotation_deg = 15.0;  // each controller turned in the hand about its grip point (each axis)
  // A strapped body tracker (hips, chest, feet, knees, elbows; issue 44): the device sits
  // strap_min_m to strap_max_m off its joint in a random direction, turned any way (a puck on a
  // belt or a strap points wherever it was put on).
  double strap_min_m = 0.02;
  double strap_max_m = 0.08;
};
// `base` (the default mounting) with one session's perturbation drawn from `seed`: the headset
// turned on the head about the eyes (T_device_joint rotation pre-multiplied by the inverse turn)
// with its eye offset moved, each controller turned about its grip point, each body role strapped
// (drawn after the headset's and controllers', so their draws do not change with it).
[[nodiscard]] Mounting draw_session_mounting(const Mounting& base, const MountingSpread& spread, std::uint64_t seed);

// `samples` (device poses through `mounting`, sorted by time) preceded by `seconds` of the
// calibration pose a user is asked for (motion/mounting.h calibration_pose_joints: the
// reference's pose at the first head sample's joint position and heading), sampled at rate_hz,
// seen through the same mounting. Throws SimError when there is no valid head sample.
// With `vary_seed`, the pose is a person's, not the reference's exactly: the head pitched and
// rolled and each wrist turned by normal draws with the reference's spreads (head_pitch_sd_deg,
// head_roll_sd_deg, hand_sd_deg), the wrists' height ratio and depth likewise.
[[nodiscard]] std::vector<TrackerSample> with_calibration_pose(const std::vector<TrackerSample>& samples,
                                                               const BodyReference& reference, const Mounting& mounting,
                                                               double rate_hz, double seconds,
                                                               std::optional<std::uint64_t> vary_seed = std::nullopt);

// `samples` preceded by `seconds` of the joints `joints` (indexed by Role) held still, sampled at
// rate_hz and seen through `mounting` as device poses (with_calibration_pose's workhorse; a
// standing frame of a clip as the calibration pose). With `body_roles`, the body trackers that
// `samples` carry are held too (rotation only where their samples are); otherwise only the
// headset and controllers (with_calibration_pose: the reference describes only those).
[[nodiscard]] std::vector<TrackerSample> with_held_pose(const std::vector<TrackerSample>& samples,
                                                        const std::array<RigidTransform, kRoleCount>& joints,
                                                        const Mounting& mounting, double rate_hz, double seconds,
                                                        bool body_roles = false);

// The true (noise-free, undelayed) trajectories of the three tracked joints of a clip.
// Immutable after construction; pose_at() is thread-safe and does not allocate.
class TrackerTrajectory {
 public:
  // Throws SimError if the clip has no frames or lacks a tracked joint.
  explicit TrackerTrajectory(const Motion& motion);

  // Valid sample with the interpolated pose of `role` at `t_ns` (clamped to the clip).
  [[nodiscard]] TrackerSample pose_at(Role role, std::int64_t t_ns) const;
  // Time of the last frame: (frames - 1) * frame_time, ns.
  [[nodiscard]] std::int64_t duration_ns() const { return duration_ns_; }
  [[nodiscard]] int frame_count() const { return frames_; }
  [[nodiscard]] double frame_time_s() const { return frame_time_s_; }

 private:
  int frames_ = 0;
  double frame_time_s_ = 0.0;
  std::int64_t duration_ns_ = 0;
  // [role][frame]
  std::array<std::vector<Vec3>, kRoleCount> positions_m_;
  std::array<std::vector<Quat>, kRoleCount> rotations_;
};

// All samples of the three roles over the clip, sorted by t_ns (ties in role order).
// Role r is sampled at true times k / rate_of(r), k = 0, 1, ... up to the last frame.
// Throws SimError for bad options or a clip without frames or tracked joints.
[[nodiscard]] std::vector<TrackerSample> simulate_trackers(const Motion& motion, const SimOptions& options);
[[nodiscard]] std::vector<TrackerSample> simulate_trackers(const TrackerTrajectory& trajectory,
                                                           const SimOptions& options);

}  // namespace bodyd
