// The diffusion method's two One Euro filters' options, one row each (issue 45 item 4): the one
// place that names a configurable option of OneEuroOptions (the tracker filter) or
// BodyFilterOptions (the body filter). The rows drive the daemon config's "filter" and
// "body_filter" keys (daemon/src/config_keys.cpp splices them in; docs/daemon.md, "Tracker
// filter" and "Body filter") and bodyd-eval's flags (filter_flag(); docs/evaluation.md), so the
// evaluation can set exactly what the daemon's config can. validate(OneEuroOptions) and
// validate(BodyFilterOptions) check the values.
// A new option: its member in one_euro.h and one row in src/filter_option_keys.cpp.
#pragma once

#include "bodyd/inference/one_euro.h"

#include <span>
#include <string>
#include <string_view>
#include <variant>

namespace bodyd {

// The two filters a row may set.
struct FilterSettings {
  OneEuroOptions& filter;
  BodyFilterOptions& body_filter;
};

struct FilterOptionKey {
  std::string_view group;  // "filter" (the tracker filter) or "body_filter"
  std::string_view name;   // the key inside the group ("min_cutoff_hz")
  std::variant<bool& (*)(FilterSettings), double& (*)(FilterSettings)> field;
  // The flag of the daemon (and bodyd-eval) for a key the daemon's command line sets: "!--no-filter"
  // (a bool flag that sets false), or "" for a key the config file alone sets.
  std::string_view daemon_flag;
  // bodyd-eval's older spellings of the flag, still taken ("--filter-beta"), comma separated, or "".
  std::string_view eval_aliases;
  std::string_view help;  // what the option does (the daemon's help; docs/daemon.md says the same)

  // "filter.min_cutoff_hz".
  [[nodiscard]] std::string full_name() const { return std::string(group) + "." + std::string(name); }
};

// Every row: the tracker filter's, then the body filter's, each in docs/daemon.md's order.
[[nodiscard]] std::span<const FilterOptionKey> filter_option_keys();

// bodyd-eval's flag of a row: the daemon's flag where it has one (--no-filter), else the group and
// key with dashes (--filter-min-cutoff-hz, --body-filter-rot-beta-per-rad-s).
[[nodiscard]] std::string filter_flag(const FilterOptionKey& row);

}  // namespace bodyd
