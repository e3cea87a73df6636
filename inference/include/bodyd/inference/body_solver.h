// Puts the tracked joints exactly on their trackers after the network (docs/model.md, "Tracked
// joints"): the Head joint on the head tracker (position and rotation) and each tracked hand on
// its tracker, even at full reach; with a hips tracker the Hips joint on it first (TrackedTargets).
//
// The network's pose is only close to the trackers (2 cm for the head on average). Moving the
// Head joint means moving its ancestors, so the correction is spread over the body by damped
// least squares (Buss 2004, "Introduction to inverse kinematics with Jacobian transpose,
// pseudoinverse and damped least squares methods") over these degrees of freedom:
//   the Hips translation, rotations of Spine, Chest and Neck, and of each clavicle (Shoulder_L/R),
// with a cost per degree of freedom (BodySolverOptions) choosing who moves: the minimum-cost
// motion that puts the Head joint on its target and brings each tracked hand's shoulder
// (UpperArm joint) within reach of its tracker. A final translation of the Hips removes what the
// iterations leave (micrometres), so the Head position is exact; the Head's rotation is then set
// to the tracker's. The arms themselves are solved afterwards by two-bone IK (two_bone_ik.h),
// which can then reach.
//
// Two targets for the head: `head_body_m`, where the body should carry it (the filtered tracker,
// see one_euro.h), and `head_m`, where the Head joint must end (the raw tracker). The body
// follows head_body_m with the costs above; the difference head_m - head_body_m (tracker noise,
// millimetres) is taken up by the neck and chest only, so tracker noise does not shake the hips.
// Does not allocate once `global` has the skeleton's size.
#pragma once

#include "bodyd/motion/skeleton.h"

#include <array>
#include <optional>

namespace bodyd {

// Skeleton indices of the joints the solver moves (names of docs/conventions.md).
struct UpperBody {
  int hips = -1, spine = -1, chest = -1, neck = -1, head = -1;
  std::array<int, 2> shoulder{-1, -1}, upper_arm{-1, -1}, lower_arm{-1, -1}, hand{-1, -1};  // left, right
};
// nullopt when a joint is missing or the chain Hips > Spine > Chest > Neck > Head,
// Chest > Shoulder > UpperArm > LowerArm > Hand is broken.
[[nodiscard]] std::optional<UpperBody> find_upper_body(const Skeleton& skeleton);

struct BodySolverOptions {
  // Costs of moving each degree of freedom, per metre (Hips) or per radian (rotations), squared
  // in the objective: a correction is spread so that cost * amount is about equal across them.
  double hips_cost_per_m = 1.0;
  double spine_cost_per_rad = 0.35;   // Spine and Chest each
  double neck_cost_per_rad = 0.2;
  double clavicle_cost_per_rad = 0.05;
  int iterations = 8;                 // Gauss-Newton steps (each with backtracking)
  double max_step_rad = 0.35;         // a joint turns at most this far per step
  double reach_fraction = 0.995;      // bring the shoulder within this fraction of the arm's length
  double max_reach_deficit_m = 0.25;  // a hand further than this out of reach is not chased
  // With a hips tracker (TrackedTargets::hips_valid) the Hips translation costs this instead: the
  // spine and neck then carry the head, and the Hips leaves its tracker only by what they cannot.
  double tracked_hips_cost_per_m = 50.0;
};

struct TrackedTargets {
  bool head_valid = false;
  Vec3 head_m = Vec3::Zero();        // the Head joint ends here (raw tracker)
  Vec3 head_body_m = Vec3::Zero();   // the body carries the head here (filtered tracker)
  Quat head_rotation = Quat::Identity();
  std::array<bool, 2> hand_valid{};  // left, right
  std::array<Vec3, 2> hand_m{Vec3::Zero(), Vec3::Zero()};
  // How far (metres, >= 0) each hand may be beyond the arm's reach before the body chases it:
  // 0 for a clean tracker; a noisy one's slack keeps its noise from pulling the body near full
  // reach (OneEuroOptions::hand_reach_slack_m).
  std::array<double, 2> hand_slack_m{};
  // A hips tracker (issue 44): the Hips joint is put on hips_m before the head is placed (then
  // see BodySolverOptions::tracked_hips_cost_per_m).
  bool hips_valid = false;
  Vec3 hips_m = Vec3::Zero();
};

struct BodySolverResult {
  double head_error_m = 0.0;                 // |Head - head_m| after solving (0 up to rounding)
  std::array<double, 2> reach_deficit_m{};   // how far each hand's target stays out of the arm's reach
};

// Solves in place: `global` must hold forward kinematics of `pose`; on return both hold the
// solution. Only the Hips translation and the local rotations of Spine, Chest, Neck, Head and the
// clavicles change. Without a valid head only the reach of the hands is solved.
BodySolverResult solve_tracked_body(const Skeleton& skeleton, const UpperBody& body, const BodySolverOptions& options,
                                    const TrackedTargets& targets, Pose& pose, GlobalPose& global);

}  // namespace bodyd
