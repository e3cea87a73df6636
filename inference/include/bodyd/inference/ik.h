// The `ik` baseline: a fixed-rule full-body pose from the head and hand trackers.
//
// Rules (docs/evaluation.md, "The ik baseline"):
//  - body heading = the tracked head's yaw; hips, spine, legs and arms start from the
//    reference standing pose (below) turned to that heading;
//  - the head's tilt relative to the upright reference (pitch, roll, yaw beyond the body
//    heading) is spread over the spine: Spine, Chest and Neck take 1/6, 1/3 and 1/2 of it
//    (cumulative, in world space) and the Head joint's global rotation is the tracked one;
//  - the hips are placed so the Head joint lands exactly on the tracked head: with an
//    upright head that is the reference's head-to-hips offset (hips below and slightly behind
//    the head), i.e. standing straight at whatever height the head is;
//  - legs keep the reference's straight standing pose; both foot contacts are true;
//  - each arm is solved by two-bone IK (two_bone_ik.h) onto its tracked hand (position and
//    rotation), elbow bending as in the reference; an arm whose hand is not valid keeps the
//    reference's hanging arm;
//  - a lost head holds the last valid head pose (tracker_valid[head] false).
//
// The reference standing pose: the BVH rest pose of the bundled data (all rotations
// identity) is not a standing pose (bones point along local +X), so the reference is a real
// standing frame shipped in the code: frame 5 of dataset-1/dataset-1_call_normal_002.bvh
// (a relaxed upright stance: straight legs, arms hanging, chosen as the most upright frame of
// the training split's "normal"-style clips), with the hips' heading removed so the body faces
// +Z, the hips above the origin and the lower toe at its height in that frame (4.5 cm).
#pragma once

#include "bodyd/inference/reconstructor.h"
#include "bodyd/inference/tracker_history.h"
#include "bodyd/inference/two_bone_ik.h"

#include <vector>

namespace bodyd {

struct StandingReference {
  Pose pose;                  // local pose on the skeleton: standing, facing +Z, hips above (0, 0)
  GlobalPose global;          // forward kinematics of `pose`
  double head_height_m = 0;   // height of the Head joint
  Vec3 head_forward_local;    // the Head joint's local axis that looks forward (+Z in the reference)
  Vec3 head_up_local;         // the Head joint's local axis that points up (+Y in the reference)
};

// The reference standing pose on `skeleton` (any bone lengths; joint names of the bundled data).
// Throws UserError naming the first joint the reference does not know.
[[nodiscard]] StandingReference standing_reference(const Skeleton& skeleton);

// The skeleton's standing head height (Head joint, metres): the "model height" of user-height
// calibration. set_head_height_m() takes the user's standing head height in the same sense (the
// height of the head tracker's Head joint when the user stands straight).
[[nodiscard]] double standing_head_height_m(const Skeleton& skeleton);

// Heading (yaw about +Y, radians, 0 = facing +Z, as quat_from_yaw) of a Head joint rotation.
// Robust to looking straight up or down: the forward axis' floor projection is completed by the
// head's up axis, which tilts forward exactly when the face tilts down.
[[nodiscard]] double head_yaw_rad(const Quat& head_rotation, const StandingReference& reference);

struct IkOptions {
  TrackerHistoryOptions history;
};

class IkReconstructor final : public Reconstructor {
 public:
  // Throws UserError if the skeleton is invalid, lacks a joint of the reference (standing_reference's)
  // or an arm chain, or its Head is not below its Hips.
  explicit IkReconstructor(const Skeleton& skeleton, const IkOptions& options = {});

  [[nodiscard]] std::string_view name() const override { return "ik"; }
  [[nodiscard]] const Skeleton& skeleton() const override { return user_skeleton_; }
  void push(const TrackerSample& sample) override { (void)history_.push(sample); }
  [[nodiscard]] std::int64_t refused_samples() const override { return history_.refused_count(); }
  [[nodiscard]] bool reconstruct(std::int64_t t_ns, BodyPose& out) override;
  void reset() override;
  void set_head_height_m(double height_m) override;
  [[nodiscard]] double head_height_m() const override { return head_height_m_; }

  [[nodiscard]] const StandingReference& reference() const { return reference_; }
  [[nodiscard]] const TrackerHistory& history() const { return history_; }

 private:
  Skeleton model_skeleton_;
  Skeleton user_skeleton_;  // model_skeleton_ scaled to the user's height
  StandingReference reference_;
  TrackerHistory history_;
  double head_height_m_ = 0;
  int hips_ = -1, head_ = -1;
  std::vector<int> spine_;  // joints strictly between Hips and Head, from the hips up
  std::array<TwoBoneChain, 2> arms_{};  // left, right

  bool have_head_ = false;
  TrackerSample last_head_;  // model scale
  Pose work_pose_;           // model scale
  GlobalPose work_global_;
};

}  // namespace bodyd
