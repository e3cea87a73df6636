// The config key table (issue 19): one row per key of the config file, the one place that
// names a key. The rows drive the config file's parser (apply_config_json), validate_config's
// per-key checks, the printer (config_to_json, --print-config) and the command-line flags
// (parse_command_line); tests/daemon/config_keys_test.cpp checks that docs/daemon.md, the
// fuzz seed tests/fuzz/config/full.json and --help list exactly these keys and flags.
//
// A new key: a member of DaemonConfig (its initializer is the default), one row in
// daemon/src/config_keys.cpp, and its line in docs/daemon.md (the "Command line" table, or the
// section the row's `doc` names). The "sim" object's keys are the simulator's own rows
// (bodyd/simulators/sim_option_keys.h), and the "filter" and "body_filter" objects' the
// filters' rows (bodyd/inference/filter_option_keys.h, which bodyd-eval's flags share), spliced in.
#pragma once

#include "bodyd/daemon/config.h"
#include "bodyd/inference/filter_option_keys.h"
#include "bodyd/simulators/sim_option_keys.h"

#include <nlohmann/json_fwd.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <variant>
#include <vector>

namespace bodyd::daemon {

using DeviceOffsets = std::array<std::optional<DeviceOffset>, kRoleCount>;

template <class T>
using ConfigRef = T& (*)(DaemonConfig&);
// The DaemonConfig member a key sets; its type says how the file's value is read and printed.
// A simulator row reads and writes config.sim through the simulator's table, a filter row
// config.filter and config.body_filter through the filters' (with_member() hides the difference).
using ConfigField = std::variant<ConfigRef<bool>, ConfigRef<int>, ConfigRef<std::size_t>, ConfigRef<double>,
                                 ConfigRef<std::string>, ConfigRef<std::vector<std::string>>, ConfigRef<DeviceOffsets>,
                                 const SimOptionKey*, const FilterOptionKey*>;

// A check CLI11 makes of a flag's value, before validation (its own message, exit 2).
enum class FlagCheck { None, Positive, NonNegative };

// Accepted values of a number key (validate_config). `error` is the message, with {key},
// {flag}, {min}, {max} and {value} replaced.
struct KeyRange {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_exclusive = false;  // > min, not >= min
  bool zero_allowed = false;   // 0 is accepted besides min .. max ("0: the model's size")
  std::string_view error{};    // "": no range check
};

struct ConfigKey {
  std::string_view group{};  // "" for a top-level key; "sim", "filter" or "body_filter" for a key inside that object
  std::string_view name{};   // the key ("replay_speed"; "min_cutoff_hz" inside "filter")
  ConfigField field{};
  // The command-line flag as CLI11 takes it: "--speed"; "!--no-filter" (a bool flag that sets
  // false); "" for a key the file alone sets. A list key's flag is repeatable.
  std::string flag{};
  FlagCheck flag_check = FlagCheck::None;
  KeyRange range{};
  // A string key's accepted values, comma separated ("diffusion,ik"); "" for any.
  std::string_view choices{};
  std::string help{};      // the flag's help (and what docs/daemon.md says)
  std::string_view doc{};  // the section of docs/daemon.md that lists the key ("Command line")
  // The file's value, for keys whose syntax is not the plain JSON of their type (outputs may be
  // objects, offsets an object of roles). Returns "" or the error.
  std::string (*read)(const nlohmann::json& value, const std::string& where, DaemonConfig& config) = nullptr;
  // The printed value, with `read`: what reads back to the same configuration.
  nlohmann::json (*print)(const DaemonConfig& config) = nullptr;

  // "sim.seed" for a key inside an object, else the name.
  [[nodiscard]] std::string full_name() const;
};

// An object of keys ("sim", "filter", "body_filter") and its messages.
struct ConfigGroup {
  std::string_view name;
  std::string_view not_object;   // the error when the value is not an object
  std::string_view unknown_key;  // the error for an unknown key inside; {keys} is replaced by the group's keys
};

// Every key, in the order of docs/daemon.md's "Command line" table (and of --help).
[[nodiscard]] std::span<const ConfigKey> config_keys();
[[nodiscard]] std::span<const ConfigGroup> config_groups();
// The row of "replay_speed" or "sim.seed", or nullptr.
[[nodiscard]] const ConfigKey* find_config_key(std::string_view full_name);

// Calls f with the DaemonConfig member the row sets (a bool&, double&, std::string&, ...), whatever
// table the row comes from; returns what f returns.
template <class F>
decltype(auto) with_member(const ConfigKey& row, DaemonConfig& config, F&& f) {
  return std::visit(
      [&](auto field) -> decltype(auto) {
        if constexpr (std::is_same_v<decltype(field), const SimOptionKey*>)
          return std::visit([&](auto sim_field) -> decltype(auto) { return f(sim_field(config.sim)); }, field->field);
        else if constexpr (std::is_same_v<decltype(field), const FilterOptionKey*>)
          return std::visit(
              [&](auto filter_field) -> decltype(auto) {
                return f(filter_field(FilterSettings{config.filter, config.body_filter}));
              },
              field->field);
        else
          return f(field(config));
      },
      row.field);
}

// Flags that set no key of their own (actions, and shorthands for a key's flag).
inline constexpr std::array<std::string_view, 10> kNonKeyFlags{
    "--config", "--user-config", "--replay", "--sim", "--gen-keys", "--client", "--list-devices", "--print-config",
    "--version", "--help"};

}  // namespace bodyd::daemon
