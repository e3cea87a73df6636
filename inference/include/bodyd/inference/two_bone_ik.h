// Analytic two-bone inverse kinematics (an arm: upper arm, lower arm, hand).
//
// Rotates the chain's first joint (upper arm, at the shoulder end) and middle joint (lower
// arm, the elbow) of a Pose so that the end joint (hand) lands exactly on a target position,
// by the law of cosines: the elbow stays in the plane spanned by the shoulder-to-target line
// and a pole point (by default the elbow's current position, so the elbow keeps bending the
// way it bent). Out of reach, the arm is clamped: fully stretched along the shoulder-to-target
// direction (or folded as far as the bone lengths allow, for targets too close). Each joint
// turns by the smallest rotation that does the job, so the bones keep their twist (or, with
// keep_hinge, the elbow keeps its bend axis). Then the
// end joint's global rotation is set to the target rotation, if one is given (otherwise the
// hand keeps its rotation relative to the lower arm).
//
// Only local rotations of the chain's three joints change; bone lengths (local translations)
// are untouched, so forward kinematics of the returned Pose reproduces the solution.
// Does not allocate when `global` already has the skeleton's size.
#pragma once

#include "bodyd/motion/skeleton.h"

#include <optional>
#include <string_view>

namespace bodyd {

// Skeleton indices of a chain upper -> lower -> end (each the parent of the next).
struct TwoBoneChain {
  int upper = -1;  // e.g. UpperArm_L: rotates about the shoulder end of the upper arm
  int lower = -1;  // e.g. LowerArm_L: the elbow
  int end = -1;    // e.g. Hand_L: the joint placed on the target
};

// The chain of three named joints, or nullopt when a name is missing or the joints are not
// parent and child in that order.
[[nodiscard]] std::optional<TwoBoneChain> find_two_bone_chain(const Skeleton& skeleton, std::string_view upper,
                                                              std::string_view lower, std::string_view end);

struct TwoBoneTarget {
  Vec3 position_m = Vec3::Zero();        // world position for the end joint
  std::optional<Quat> rotation;          // world (global) rotation for the end joint
  std::optional<Vec3> pole_m;            // world point the elbow bends toward; default: current elbow
  // Treat the middle joint as a hinge: keep the axis the lower bone currently bends about (fixed in
  // the upper bone's frame) and twist the upper bone so that axis is normal to the new bend plane;
  // the lower joint then only flexes about it. Keeps an elbow's relation to its upper arm the way
  // the current pose has it (e.g. a reference pose's), instead of carrying the upper arm's twist
  // along. Falls back to the smallest rotations when the current chain is straight (bend < 1 deg).
  bool keep_hinge = false;
  // Soft reach (metres, >= 0; 0: off). The law of cosines makes the elbow swing fast near a
  // straight arm: a millimetre of target motion there moves it by centimetres, so a noisy target
  // shakes the elbow. Within soft_zone_m of full reach the chain's reach follows the target's
  // distance d on an exponential, full - z + z (1 - exp(-(d - full + z) / z)), which has slope 1
  // where the zone starts and never reaches full length: the elbow's motion stays bounded, and the
  // end joint falls short of the target by up to 0.37 z at full reach (more beyond it).
  double soft_zone_m = 0.0;
};

struct TwoBoneResult {
  bool reachable = false;      // the target was within reach (the end joint is on it)
  double error_m = 0.0;        // distance from the end joint to the target after solving
};

// Solves in place. `global` must hold forward kinematics of `pose` on entry; on return
// `pose` and `global` (recomputed by forward kinematics) hold the solution. A chain whose
// bones have zero length is left unchanged (result: not reachable, error the distance).
TwoBoneResult solve_two_bone_ik(const Skeleton& skeleton, const TwoBoneChain& chain, const TwoBoneTarget& target,
                                Pose& pose, GlobalPose& global);

}  // namespace bodyd
