#include "bodyd/base/spec_options.h"

#include <algorithm>

namespace bodyd {

std::pair<std::string_view, std::string_view> split_spec_query(std::string_view text) {
  const auto q = text.find('?');
  if (q == std::string_view::npos) return {text, {}};
  return {text.substr(0, q), text.substr(q + 1)};
}

std::string parse_spec_options(std::string_view query, std::vector<SpecOption>& out) {
  out.clear();
  while (!query.empty()) {
    const auto amp = query.find('&');
    const std::string_view item = query.substr(0, amp);
    query = amp == std::string_view::npos ? std::string_view() : query.substr(amp + 1);
    const auto eq = item.find('=');
    if (eq == std::string_view::npos || eq == 0) return "option \"" + std::string(item) + "\" is not KEY=VALUE";
    SpecOption o{std::string(item.substr(0, eq)), std::string(item.substr(eq + 1))};
    if (std::any_of(out.begin(), out.end(), [&](const SpecOption& x) { return x.key == o.key; }))
      return "option \"" + o.key + "\" given twice";
    out.push_back(std::move(o));
  }
  return {};
}

}  // namespace bodyd
