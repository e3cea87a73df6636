// A deterministic synthetic pose stream (no model involved), for tests, demos and the
// bodyd-testpub tool: every value is a function of the sequence number, so a receiver can
// check exactly what it decoded.
#pragma once

#include "bodyd/protocol/pose_message.h"

#include <cstdint>

namespace bodyd::protocol {

// A 22-joint skeleton with the names and hierarchy of the bundled motion data
// (joint_Root, Hips, Spine, ..., Toes_R); skeleton_id is set.
[[nodiscard]] SkeletonMessage synthetic_skeleton();

// The pose number `seq` of the synthetic stream on synthetic_skeleton(): joint positions and
// rotations vary smoothly with seq, t_ns = start_t_ns + seq * period_ns, publish_t_ns =
// t_ns + 1 ms, flags and foot contacts cycle through their values. Root = joint 1 (Hips).
[[nodiscard]] PoseMessage synthetic_pose(std::uint64_t seq, std::int64_t start_t_ns = 1'000'000'000,
                                         std::int64_t period_ns = 11'111'111);

}  // namespace bodyd::protocol
