#include "bodyd/inference/body_solver.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <string_view>

namespace bodyd {

namespace {

// Degrees of freedom: Hips translation, then rotation vectors (world axes) of these joints.
constexpr int kDofs = 18;
constexpr int kTasks = 5;  // head position (3), left and right shoulder reach (1 each)
enum Dof { kHipsT = 0, kSpineR = 3, kChestR = 6, kNeckR = 9, kClavicleLR = 12, kClavicleRR = 15 };
using Jacobian = Eigen::Matrix<double, kTasks, kDofs>;
using DofVector = Eigen::Matrix<double, kDofs, 1>;
using TaskVector = Eigen::Matrix<double, kTasks, 1>;

bool is_child(const Skeleton& s, int child, int parent) {
  return child >= 0 && parent >= 0 && s.parents[static_cast<size_t>(child)] == parent;
}

// Columns of a rotation DOF (world rotation vector of `joint`) for an effector at p:
// d p / d w = w x (p - p_joint).
void rotation_columns(Jacobian& J, int row, int col, const Vec3& p, const Vec3& joint) {
  const Vec3 r = p - joint;
  for (int a = 0; a < 3; ++a) J.block<3, 1>(row, col + a) = Vec3::Unit(a).cross(r);
}

void rotate_joint(const Skeleton& skeleton, int joint, const Vec3& w, double max_rad, const GlobalPose& global,
                  Pose& pose) {
  const double angle = w.norm();
  if (angle < 1e-12) return;
  const Quat turn(Eigen::AngleAxisd(std::min(angle, max_rad), w / angle));
  const auto j = static_cast<size_t>(joint);
  const int parent = skeleton.parents[j];
  const Quat g_parent = parent >= 0 ? global.rotations[static_cast<size_t>(parent)] : Quat::Identity();
  pose.local_rotations[j] = (g_parent.conjugate() * turn * global.rotations[j]).normalized();
}

void translate_hips(const Skeleton& skeleton, int hips, const Vec3& delta, const GlobalPose& global, Pose& pose) {
  const int parent = skeleton.parents[static_cast<size_t>(hips)];
  const Quat g_parent = parent >= 0 ? global.rotations[static_cast<size_t>(parent)] : Quat::Identity();
  pose.local_translations[static_cast<size_t>(hips)] += g_parent.conjugate() * delta;
}

}  // namespace

std::optional<UpperBody> find_upper_body(const Skeleton& s) {
  UpperBody b;
  b.hips = s.find("Hips");
  b.spine = s.find("Spine");
  b.chest = s.find("Chest");
  b.neck = s.find("Neck");
  b.head = s.find("Head");
  if (!is_child(s, b.spine, b.hips) || !is_child(s, b.chest, b.spine) || !is_child(s, b.neck, b.chest) ||
      !is_child(s, b.head, b.neck))
    return std::nullopt;
  constexpr std::string_view kSide[2] = {"_L", "_R"};
  for (size_t i = 0; i < 2; ++i) {
    const std::string side(kSide[i]);
    b.shoulder[i] = s.find("Shoulder" + side);
    b.upper_arm[i] = s.find("UpperArm" + side);
    b.lower_arm[i] = s.find("LowerArm" + side);
    b.hand[i] = s.find("Hand" + side);
    if (!is_child(s, b.shoulder[i], b.chest) || !is_child(s, b.upper_arm[i], b.shoulder[i]) ||
        !is_child(s, b.lower_arm[i], b.upper_arm[i]) || !is_child(s, b.hand[i], b.lower_arm[i]))
      return std::nullopt;
  }
  return b;
}

BodySolverResult solve_tracked_body(const Skeleton& skeleton, const UpperBody& b, const BodySolverOptions& o,
                                    const TrackedTargets& t, Pose& pose, GlobalPose& global) {
  BodySolverResult result;
  const auto P = [&](int j) -> const Vec3& { return global.positions[static_cast<size_t>(j)]; };
  std::array<double, 2> arm{}, reach{};  // the arm's length; the shoulder-to-hand distance the body keeps
  for (size_t s = 0; s < 2; ++s) {
    arm[s] = skeleton.offsets[static_cast<size_t>(b.lower_arm[s])].norm() +
             skeleton.offsets[static_cast<size_t>(b.hand[s])].norm();
    reach[s] = o.reach_fraction * arm[s] + (std::isfinite(t.hand_slack_m[s]) ? std::max(0.0, t.hand_slack_m[s]) : 0.0);
  }
  // The reach of a tracked hand as a one-dimensional task on its shoulder (UpperArm joint): its
  // distance to the hand's target may not exceed `reach`. Active within kBand of the limit (with
  // zero error inside it) so that iterations do not toggle it and undo each other.
  constexpr double kBand = 0.02;
  const auto reach_row = [&](size_t s, Vec3& dir) -> std::optional<double> {
    if (!t.hand_valid[s]) return std::nullopt;
    const Vec3 d = t.hand_m[s] - P(b.upper_arm[s]);
    const double n = d.norm();
    if (n < 1e-9 || n < reach[s] - kBand) return std::nullopt;
    dir = d / n;
    return std::min(std::max(0.0, n - reach[s]), o.max_reach_deficit_m);
  };
  const auto add_reach = [&](Jacobian& J, TaskVector& e, size_t s, bool clavicle_only) {
    Vec3 dir;
    const std::optional<double> need = reach_row(s, dir);
    if (!need) return false;
    const int row = 3 + static_cast<int>(s);
    const Vec3 shoulder = P(b.upper_arm[s]);
    Jacobian tmp = Jacobian::Zero();  // rows 0..2: the shoulder's motion
    if (!clavicle_only) {
      tmp.block<3, 3>(0, kHipsT).setIdentity();
      rotation_columns(tmp, 0, kSpineR, shoulder, P(b.spine));
      rotation_columns(tmp, 0, kChestR, shoulder, P(b.chest));
    }
    rotation_columns(tmp, 0, s == 0 ? kClavicleLR : kClavicleRR, shoulder, P(b.shoulder[s]));
    J.row(row) = dir.transpose() * tmp.topRows<3>();
    e(row) = *need;
    return *need > 0.0;
  };

  // Minimum-cost solution of J dq = e: dq = C^-2 J^T (J C^-2 J^T + eps I)^-1 e, computed as the
  // damped normal equations with a small damping so the tasks are met (the costs only choose how).
  DofVector inv_cost2;
  const auto set_cost = [&](int dof, double c) { inv_cost2.segment<3>(dof).setConstant(1.0 / (c * c)); };
  const auto solve = [&](const Jacobian& J, const TaskVector& e) -> DofVector {
    const Eigen::Matrix<double, kDofs, kTasks> JtC = inv_cost2.asDiagonal() * J.transpose();
    Eigen::Matrix<double, kTasks, kTasks> A = J * JtC;
    A.diagonal().array() += 1e-6;
    return JtC * A.ldlt().solve(e);
  };
  const auto apply_step = [&](const DofVector& dq) {
    translate_hips(skeleton, b.hips, dq.segment<3>(kHipsT), global, pose);
    rotate_joint(skeleton, b.spine, dq.segment<3>(kSpineR), o.max_step_rad, global, pose);
    rotate_joint(skeleton, b.chest, dq.segment<3>(kChestR), o.max_step_rad, global, pose);
    rotate_joint(skeleton, b.neck, dq.segment<3>(kNeckR), o.max_step_rad, global, pose);
    rotate_joint(skeleton, b.shoulder[0], dq.segment<3>(kClavicleLR), o.max_step_rad, global, pose);
    rotate_joint(skeleton, b.shoulder[1], dq.segment<3>(kClavicleRR), o.max_step_rad, global, pose);
    forward_kinematics(skeleton, pose, global);
  };
  // The squared error of the tasks (head target `head_goal` when given, reach of the hands).
  const auto task_error = [&](const Vec3* head_goal) {
    double err = head_goal != nullptr ? (*head_goal - P(b.head)).squaredNorm() : 0.0;
    for (size_t s = 0; s < 2; ++s) {
      if (!t.hand_valid[s]) continue;
      const double over = (t.hand_m[s] - P(b.upper_arm[s])).norm() - reach[s];
      if (over > 0.0) err += std::min(over, o.max_reach_deficit_m) * std::min(over, o.max_reach_deficit_m);
    }
    return err;
  };
  // A Gauss-Newton step with backtracking: the step is halved (up to 4 times) while it would
  // increase the error, as the coupled head and shoulder tasks are far from linear.
  const std::array<int, 6> moved{b.hips, b.spine, b.chest, b.neck, b.shoulder[0], b.shoulder[1]};
  std::array<Quat, 6> saved_rotations;
  Vec3 saved_hips = Vec3::Zero();
  const auto apply = [&](const DofVector& dq, const Vec3* head_goal) {
    const double before = task_error(head_goal);
    for (size_t i = 0; i < moved.size(); ++i) saved_rotations[i] = pose.local_rotations[static_cast<size_t>(moved[i])];
    saved_hips = pose.local_translations[static_cast<size_t>(b.hips)];
    double scale = 1.0;
    for (int k = 0; k < 5; ++k, scale *= 0.5) {
      apply_step(scale * dq);
      if (task_error(head_goal) < before) return;
      for (size_t i = 0; i < moved.size(); ++i) pose.local_rotations[static_cast<size_t>(moved[i])] = saved_rotations[i];
      pose.local_translations[static_cast<size_t>(b.hips)] = saved_hips;
      forward_kinematics(skeleton, pose, global);
    }
  };

  // Stage 0: a tracked Hips goes onto its tracker (its rotation stays the network's: turning it
  // to the tracker's as well made the body jerkier on unseen styles, docs/models.md).
  if (t.hips_valid) {
    translate_hips(skeleton, b.hips, t.hips_m - P(b.hips), global, pose);
    forward_kinematics(skeleton, pose, global);
  }
  // Stage 1: the body carries the head to head_body_m and the shoulders within reach.
  set_cost(kHipsT, t.hips_valid ? o.tracked_hips_cost_per_m : o.hips_cost_per_m);
  set_cost(kSpineR, o.spine_cost_per_rad);
  set_cost(kChestR, o.spine_cost_per_rad);
  set_cost(kNeckR, o.neck_cost_per_rad);
  set_cost(kClavicleLR, o.clavicle_cost_per_rad);
  set_cost(kClavicleRR, o.clavicle_cost_per_rad);
  for (int it = 0; it < o.iterations; ++it) {
    Jacobian J = Jacobian::Zero();
    TaskVector e = TaskVector::Zero();
    bool any = false;
    if (t.head_valid) {
      const Vec3 head = P(b.head);
      e.segment<3>(0) = t.head_body_m - head;
      J.block<3, 3>(0, kHipsT).setIdentity();
      rotation_columns(J, 0, kSpineR, head, P(b.spine));
      rotation_columns(J, 0, kChestR, head, P(b.chest));
      rotation_columns(J, 0, kNeckR, head, P(b.neck));
      any = any || e.segment<3>(0).squaredNorm() > 1e-14;
    }
    for (size_t s = 0; s < 2; ++s) any = add_reach(J, e, s, false) || any;
    if (!any) break;
    apply(solve(J, e), t.head_valid ? &t.head_body_m : nullptr);
  }

  if (t.head_valid) {
    // Stage 2: the rest, head_m - Head (tracker noise, filter lag, what stage 1 left): across the
    // neck by the neck and chest; along it (which they cannot do) by the whole body below.
    inv_cost2.setZero();
    set_cost(kChestR, 1.0);
    set_cost(kNeckR, 0.25);
    for (int it = 0; it < 2; ++it) {
      const Vec3 head = P(b.head);
      const Vec3 err = t.head_m - head;
      if (err.squaredNorm() < 1e-14) break;
      Jacobian J = Jacobian::Zero();
      TaskVector e = TaskVector::Zero();
      e.segment<3>(0) = err;
      rotation_columns(J, 0, kChestR, head, P(b.chest));
      rotation_columns(J, 0, kNeckR, head, P(b.neck));
      apply(solve(J, e), &t.head_m);
    }
    // Exact: whatever is left moves the whole body.
    const Vec3 rest = t.head_m - P(b.head);
    if (rest.squaredNorm() > 0.0) {
      translate_hips(skeleton, b.hips, rest, global, pose);
      forward_kinematics(skeleton, pose, global);
    }
    const auto head = static_cast<size_t>(b.head);
    pose.local_rotations[head] =
        (global.rotations[static_cast<size_t>(b.neck)].conjugate() * t.head_rotation.normalized()).normalized();
    forward_kinematics(skeleton, pose, global);
    result.head_error_m = (P(b.head) - t.head_m).norm();
  }

  // Stage 3: what stage 2 took back from the reach, by the clavicles alone (they do not move
  // the head).
  inv_cost2.setZero();
  set_cost(kClavicleLR, 1.0);
  set_cost(kClavicleRR, 1.0);
  for (int it = 0; it < 4; ++it) {
    Jacobian J = Jacobian::Zero();
    TaskVector e = TaskVector::Zero();
    bool any = false;
    for (size_t s = 0; s < 2; ++s) any = add_reach(J, e, s, true) || any;
    if (!any) break;
    apply(solve(J, e), nullptr);
  }
  for (size_t s = 0; s < 2; ++s)
    result.reach_deficit_m[s] =
        t.hand_valid[s] ? std::max(0.0, (t.hand_m[s] - P(b.upper_arm[s])).norm() - arm[s]) : 0.0;
  return result;
}

}  // namespace bodyd
