// The options of a spec (an --output or --source argument): SCHEME:TARGET?KEY=VALUE&KEY=VALUE.
// One rule for every spec (docs/outputs.md, docs/drivers.md): the options are what follows the
// first '?', separated by '&'; each is KEY=VALUE with a non-empty KEY (the VALUE may be empty, and
// holds everything after the first '='); a trailing '&' is allowed, an empty option between two
// '&' is not; a KEY given twice is refused. Which keys a spec takes is the caller's business.
#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace bodyd {

struct SpecOption {
  std::string key, value;
  bool operator==(const SpecOption&) const = default;
};

// `text` split at its first '?': {text before it, options after it}; {text, ""} when there is no '?'.
[[nodiscard]] std::pair<std::string_view, std::string_view> split_spec_query(std::string_view text);

// Parses the part after '?' into `out` (in the order given). Returns "" on success, else what is
// wrong, for the caller to prefix with the spec: option "ITEM" is not KEY=VALUE / option "KEY" given twice.
[[nodiscard]] std::string parse_spec_options(std::string_view query, std::vector<SpecOption>& out);

}  // namespace bodyd
