// The online reconstructor: the one object the daemon and the evaluation both use.
//
// It takes tracker samples at any rate and in any interleaving of roles, and produces
// the full-body pose at a requested time using only samples with t_ns <= that time
// (causal). Implementations: the diffusion model (DiffusionReconstructor) and the
// fixed-rule baseline (IkReconstructor). Not thread-safe: one thread drives one object.
#pragma once

#include "bodyd/motion/skeleton.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <cstdint>
#include <string_view>

namespace bodyd {

struct BodyPose {
  std::int64_t t_ns = 0;                    // the time the pose is for
  Pose pose;                                // local pose on skeleton() (user scale, metres)
  GlobalPose global;                        // forward kinematics of `pose`
  std::array<bool, 2> foot_contact{};       // left, right (Toes_L, Toes_R)
  std::array<bool, kRoleCount> tracker_valid{};  // the trackers observed at t_ns (head, left, right)
};

class Reconstructor {
 public:
  virtual ~Reconstructor() = default;

  [[nodiscard]] virtual std::string_view name() const = 0;
  // The skeleton of every output pose (the model's skeleton, scaled to the user's height).
  [[nodiscard]] virtual const Skeleton& skeleton() const = 0;

  // Feeds one sample. Within one role, t_ns must not decrease (older samples are ignored
  // and counted); roles may interleave freely. Does not allocate once warmed up.
  // A sample with non-finite or implausible values (tracker_sample_plausible() in
  // tracker_history.h: positions beyond limits::kMaxAbsPositionM, a quaternion that is not
  // unit length, a time beyond limits::kMaxAbsTimeNs) is refused and counted, never stored:
  // one bad sample cannot poison later poses.
  virtual void push(const TrackerSample& sample) = 0;
  // Samples push() refused for their values, since construction (reset() keeps the count).
  [[nodiscard]] virtual std::int64_t refused_samples() const { return 0; }

  // The pose at t_ns from samples with time <= t_ns. Successive calls must have increasing t_ns.
  // Returns false (and leaves `out` unchanged) until a valid head sample has been seen.
  [[nodiscard]] virtual bool reconstruct(std::int64_t t_ns, BodyPose& out) = 0;

  // Forgets all samples and emitted frames (a new user or a new recording).
  virtual void reset() = 0;

  // Size calibration by the user's standing *head* height (the Head joint's height standing
  // straight; not the body height: the config's user_height_m is the body height, converted
  // with the daemon's kHeadHeightPerStature, config.h). Tracker positions are scaled by
  // model_head_height / height_m on the way in and back on the way out. <= 0 restores the
  // model's own height.
  virtual void set_head_height_m(double height_m) = 0;
  [[nodiscard]] virtual double head_height_m() const = 0;
};

}  // namespace bodyd
