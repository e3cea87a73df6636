// The simulator's options, one row each (issue 19): the one place that names an option of
// SimOptions. The rows drive the daemon config's "sim" keys (docs/daemon.md), the flags of
// bodyd-sim and bodyd-eval (docs/simulator.md, docs/evaluation.md; the daemon's own are
// "--sim-" + the flag's name, e.g. --sim-seed), SimOptions::validate() and the help texts.
// A new option is one member of SimOptions and one row in src/sim_option_keys.cpp.
#pragma once

#include "bodyd/simulators/tracker_sim.h"

#include <cstdint>
#include <span>
#include <string_view>
#include <variant>

namespace bodyd {

struct SimOptionKey {
  std::string_view key;      // the config's "sim" key; SimOptions::validate()'s messages name it
  std::string_view flag;     // the canonical flag of bodyd-sim and bodyd-eval ("--noise-mm")
  std::string_view aliases;  // older spellings the tools still take, comma separated ("--dropout-ms"), or ""
  // The SimOptions member the option sets.
  std::variant<double& (*)(SimOptions&), std::uint64_t& (*)(SimOptions&)> field;
  // Accepted values of a number (validate()): min .. max, finite; with zero_means_unset 0 is
  // accepted too (a role's rate: 0 uses rate_hz). An integer row accepts its whole type.
  double min = 0.0, max = 0.0;
  bool zero_means_unset = false;
  std::string_view unit;          // in validate()'s message, after the range (" Hz")
  std::string_view message_name;  // validate()'s name for it when not `key` ("role_rate_hz[head]")
  std::string_view help;          // the flags' help (the docs say the same)
};

// Every row, in the order of SimOptions and of validate()'s checks.
[[nodiscard]] std::span<const SimOptionKey> sim_option_keys();
// The row of a "sim" key, or nullptr.
[[nodiscard]] const SimOptionKey* find_sim_option_key(std::string_view key);

}  // namespace bodyd
