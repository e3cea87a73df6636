#include "bodyd/inference/sample_conditioning.h"

#include "bodyd/inference/features.h"
#include "bodyd/motion/tracker_log.h"

#include <cmath>

namespace bodyd {

void SampleConditioner::condition(TrackerSample& s) {
  if (s.frame == PoseFrame::Device) {
    device_frames_seen_[static_cast<int>(s.role)] = true;
    s = device_to_joint(s, mounting_.T_device_joint[static_cast<int>(s.role)]);
  }
  if (!s.valid) return;
  if (const auto& o = offsets_[static_cast<int>(s.role)]) {
    s.position_m = s.position_m + s.rotation * o->position_m;
    s.rotation = (s.rotation * o->rotation).normalized();
  }
  if (recentred_) {
    s.position_m = recentre_rotation_ * s.position_m + recentre_translation_m_;
    s.rotation = (recentre_rotation_ * s.rotation).normalized();
  }
}

void SampleConditioner::finish(TrackerSample& s) {
  if (s.valid) s.rotation = unit_rotation(s.rotation);
}

Recentring SampleConditioner::recentre_on(TrackerSample& head) {
  const features::Canonical c = features::canonical_from_head(head.position_m, head.rotation);
  recentre_rotation_ = (c.R_canon_world * recentre_rotation_).normalized();
  recentre_translation_m_ = c.R_canon_world * (recentre_translation_m_ - c.origin_m);
  recentred_ = true;
  head.position_m = c.R_canon_world * (head.position_m - c.origin_m);
  head.rotation = (c.R_canon_world * head.rotation).normalized();
  return {c.yaw_rad * 180.0 / M_PI, c.origin_m};
}

void SampleConditioner::to_runtime_space(const BodyPose& body, BodyPose& out) const {
  out = body;  // same sizes after the first: vector assignment reuses the storage
  if (!recentred_) return;
  const Quat undo = recentre_rotation_.conjugate();
  for (std::size_t k = 0; k < out.global.positions.size(); ++k) {
    out.global.positions[k] = undo * (body.global.positions[k] - recentre_translation_m_);
    out.global.rotations[k] = (undo * body.global.rotations[k]).normalized();
  }
  // The root (joint 0) carries the world transform of the local pose.
  if (!out.pose.local_translations.empty())
    out.pose.local_translations[0] = undo * (body.pose.local_translations[0] - recentre_translation_m_);
  if (!out.pose.local_rotations.empty()) out.pose.local_rotations[0] = (undo * body.pose.local_rotations[0]).normalized();
}

}  // namespace bodyd
