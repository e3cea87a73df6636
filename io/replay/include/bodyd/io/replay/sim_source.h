// Simulated devices: the head and hand trackers a person performing a motion-capture clip
// would produce (the tracker simulator, docs/simulator.md), delivered through the same
// interface as real devices, paced by their timestamps (or fast, or looped: ReplayOptions).
#pragma once

#include "bodyd/io/replay/replay_source.h"
#include "bodyd/io/source.h"
#include "bodyd/simulators/tracker_sim.h"

#include <filesystem>
#include <memory>
#include <string>

namespace bodyd::drivers {

// Reads the BVH clip and simulates its trackers with `sim`. Returns nullptr and sets
// `error` when the clip cannot be read or the options are invalid.
[[nodiscard]] std::unique_ptr<TrackerSource> open_sim_source(const std::filesystem::path& bvh_path,
                                                             const SimOptions& sim,
                                                             const ReplayOptions& replay,
                                                             std::string& error);

}  // namespace bodyd::drivers
