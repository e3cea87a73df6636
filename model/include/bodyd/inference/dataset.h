// Training windows from motion capture, built with the runtime's feature code (features.h).
#pragma once

#include "bodyd/inference/features.h"
#include "bodyd/motion/bvh.h"

#include <vector>

namespace bodyd::features {

// Global poses and contact labels of every frame of a clip.
struct ClipFeatures {
  std::vector<GlobalPose> global;
  std::vector<std::array<bool, 2>> contact;
};
[[nodiscard]] ClipFeatures clip_features(const Motion& motion);

// Appends to `out` the feature windows of a clip: windows of `window` frames ending at frames
// 0, stride, 2*stride, ... (frames before the clip's start repeat frame 0), each in the canonical
// frame of its newest frame. Returns the number of windows appended (each window*kDim floats).
int append_windows(const ClipFeatures& clip, int window, int stride, std::vector<float>& out);

}  // namespace bodyd::features
