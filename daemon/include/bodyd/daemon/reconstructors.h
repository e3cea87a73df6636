// The daemon's reconstructor factory: make_reconstructor() (inference/factory.h) with what the
// daemon knows (the ik method's skeleton from a BVH file) and error messages that say what to do.
#pragma once

#include "bodyd/daemon/daemon.h"

#include <filesystem>

namespace bodyd::daemon {

// `skeleton_bvh` gives the skeleton of the ik method (its first lines; the motion is not used).
[[nodiscard]] ReconstructorFactory make_default_factory(const std::filesystem::path& skeleton_bvh);

}  // namespace bodyd::daemon
