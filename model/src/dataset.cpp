#include "bodyd/inference/dataset.h"

#include <algorithm>

namespace bodyd::features {

ClipFeatures clip_features(const Motion& motion) {
  ClipFeatures c;
  const size_t n = motion.frames.size();
  c.global.resize(n);
  c.contact.resize(n);
  for (size_t f = 0; f < n; ++f) forward_kinematics(motion.skeleton, motion.frames[f], c.global[f]);
  for (size_t f = 0; f < n; ++f) {
    // Frame 0 has no predecessor: use frame 1 as the other end of the difference.
    const size_t a = f == 0 ? std::min<size_t>(1, n - 1) : f - 1;
    c.contact[f] = contact_labels(c.global[a], c.global[f], motion.frame_time_s);
  }
  return c;
}

int append_windows(const ClipFeatures& clip, int window, int stride, std::vector<float>& out) {
  const int n = static_cast<int>(clip.global.size());
  int count = 0;
  for (int end = 0; end < n; end += stride) {
    const GlobalPose& newest = clip.global[static_cast<size_t>(end)];
    const Canonical c = canonical_from_head(newest.positions[kHead], newest.rotations[kHead]);
    const size_t base = out.size();
    out.resize(base + static_cast<size_t>(window) * kDim);
    for (int w = 0; w < window; ++w) {
      const int f = std::max(0, end - (window - 1) + w);
      encode_pose(clip.global[static_cast<size_t>(f)], clip.contact[static_cast<size_t>(f)], c,
                  Frame(out.data() + base + static_cast<size_t>(w) * kDim, kDim));
    }
    ++count;
  }
  return count;
}

}  // namespace bodyd::features
