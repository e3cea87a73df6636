// The simulator's command-line flags, one per row of sim_option_keys(): what bodyd-sim and
// bodyd-eval register (bodyd's --sim-seed and the other --sim- flags come from the same rows
// through its config key table). Header-only so that the simulators library itself needs no
// CLI11; include it only where CLI11 is linked.
#pragma once

#include "bodyd/simulators/sim_option_keys.h"
#include "bodyd/simulators/tracker_sim.h"

#include <CLI/CLI.hpp>

#include <string>
#include <optional>
#include <string_view>

namespace bodyd {

struct SimFlagStyle {
  std::string_view prefix;       // put after "--": "sim-" makes --noise-mm --sim-noise-mm
  bool aliases = true;           // also take each row's older spellings
  bool show_defaults = true;     // the help shows the current value
  std::string_view help_suffix;  // appended to every row's help
};

// The flag of `row` as `style` spells it ("--sim-noise-mm").
[[nodiscard]] inline std::string sim_flag_name(const SimOptionKey& row, const SimFlagStyle& style = {}) {
  return "--" + std::string(style.prefix) + std::string(row.flag.substr(2));
}

// Adds one option per row, writing into `options` (which must outlive the parse).
inline void add_sim_flags(CLI::App& app, SimOptions& options, const SimFlagStyle& style = {}) {
  for (const SimOptionKey& row : sim_option_keys()) {
    std::string names = sim_flag_name(row, style);
    if (style.aliases && !row.aliases.empty()) names += "," + std::string(row.aliases);
    const std::string help = std::string(row.help) + std::string(style.help_suffix);
    CLI::Option* option = std::visit([&](auto field) { return app.add_option(names, field(options), help); }, row.field);
    if (style.show_defaults) option->capture_default_str();
  }
}

// --device-frames joint|xr (default: what `device_frames` holds, "joint"): whether the simulated
// trackers are the skeleton's joints or what a headset and controllers send (docs/simulator.md);
// `help` says what the tool does with each.
inline void add_device_frames_flag(CLI::App& app, std::string& device_frames, const std::string& help) {
  app.add_option("--device-frames", device_frames, help)->check(CLI::IsMember({"joint", "xr"}))->capture_default_str();
}

// --trackers SET (default head,hands): the simulated roles, parse_tracker_set's syntax
// (docs/conventions.md, "Tracker roles"), into opt.roles and opt.rotation_only; a bad set is a
// usage error naming what is accepted.
inline void add_trackers_flag(CLI::App& app, SimOptions& opt) {
  app.add_option_function<std::string>(
         "--trackers",
         [&opt](const std::string& text) {
           std::string error;
           const std::optional<TrackerSet> set = parse_tracker_set(text, error);
           if (!set) throw CLI::ValidationError("--trackers", error);
           opt.roles = set->roles;
           opt.rotation_only = set->rotation_only;
         },
         "the tracked roles (default head,hands): a comma list of head, left_hand, right_hand, hips, chest, "
         "left_foot, right_foot, left_knee, right_knee, left_elbow, right_elbow or the groups hands, feet, knees, "
         "elbows, each optionally followed by :rot (rotation only, an IMU tracker), e.g. head,hands,hips:rot,feet:rot; "
         "head required");
}

}  // namespace bodyd
