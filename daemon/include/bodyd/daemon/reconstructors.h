// The daemon's reconstructor factory: make_reconstructor() (inference/factory.h) with what the
// daemon knows (the ik method's skeleton from a BVH file) and error messages that say what to do.
#pragma once

#include "bodyd/daemon/daemon.h"
#include "bodyd/inference/factory.h"

#include <filesystem>

namespace bodyd::daemon {

// `skeleton_bvh` gives the skeleton of the ik method (its first lines; the motion is not used);
// `options` go to every reconstructor made (the diffusion's tracker filter: config "filter").
[[nodiscard]] ReconstructorFactory make_default_factory(const std::filesystem::path& skeleton_bvh,
                                                        const ReconstructorOptions& options = {});

}  // namespace bodyd::daemon
