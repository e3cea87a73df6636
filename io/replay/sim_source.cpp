#include "bodyd/io/replay/sim_source.h"
#include "bodyd/io/open_source.h"

#include "bodyd/motion/bvh.h"

namespace bodyd::drivers {

std::unique_ptr<TrackerSource> open_sim_source(const std::filesystem::path& bvh_path, const SimOptions& sim,
                                               const ReplayOptions& replay, std::string& error) {
  if (const std::string bad = sim.validate(); !bad.empty()) {
    error = "simulated trackers: " + bad;
    return nullptr;
  }
  std::error_code ec;
  if (!std::filesystem::is_regular_file(bvh_path, ec)) {
    error = bvh_path.string() + ": no such BVH clip for the simulated trackers";
    return nullptr;
  }
  try {
    const Motion motion = read_bvh(bvh_path);
    std::vector<TrackerSample> samples = simulate_trackers(motion, sim);
    return make_replay_source("sim:" + bvh_path.string(), std::move(samples), replay);
  } catch (const std::exception& e) {
    error = e.what();
    return nullptr;
  }
}

// The registry's factory (sources.cpp): sim:FILE.bvh.
std::unique_ptr<TrackerSource> open_sim_spec(const SourceSpec& spec, const SourceOptions& options, std::string& error) {
  return open_sim_source(spec.argument, options.sim, options.replay, error);
}

}  // namespace bodyd::drivers
