// Pose -> message conversion: the reconstructor's skeleton and poses as the protocol's
// skeleton and pose messages (docs/protocol.md). Pure functions, no I/O.
#pragma once

#include "bodyd/inference/reconstructor.h"
#include "bodyd/motion/skeleton.h"
#include "bodyd/protocol/pose_message.h"

#include <nlohmann/json.hpp>

#include <cstdint>

namespace bodyd::daemon {

// The skeleton message of a reconstruction skeleton (skeleton_id computed). For the bundled
// data's humanoid it carries the reference T-pose (motion/humanoid.h, docs/protocol.md "Rest
// pose"): rest rotations, and the Hips offset at its standing height above joint_Root (the
// BVH's is a clip's world position); any other skeleton gets a version-1 message, its offsets
// as they are and no rest rotations.
[[nodiscard]] protocol::SkeletonMessage skeleton_message(const Skeleton& skeleton);

// The control reply's "rest_rotations_xyzw" (docs/control.md): [[x, y, z, w], ...], or null
// when the skeleton has none.
[[nodiscard]] nlohmann::json rest_rotations_json(const protocol::SkeletonMessage& skeleton);

// What a pose message carries besides the pose.
struct PoseMessageContext {
  std::uint64_t seq = 0;
  std::int64_t t_ns = 0;
  std::uint32_t skeleton_id = 0;
  int root_joint = -1;  // the Hips joint's index, or -1
  bool height_calibrated = false;
  bool offsets_configured = false;
};

// Fills `out` from `body` (reusing its storage: no allocation once sized). publish_t_ns is
// left to the caller (stamped right before encoding).
void fill_pose_message(const BodyPose& body, const PoseMessageContext& context, protocol::PoseMessage& out);

}  // namespace bodyd::daemon
