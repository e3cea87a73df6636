// The simulator's command-line flags, one per row of sim_option_keys(): what bodyd-sim and
// bodyd-eval register (bodyd's --sim-seed and the other --sim- flags come from the same rows
// through its config key table). Header-only so that the simulators library itself needs no
// CLI11; include it only where CLI11 is linked.
#pragma once

#include "bodyd/simulators/sim_option_keys.h"

#include <CLI/CLI.hpp>

#include <string>
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

}  // namespace bodyd
