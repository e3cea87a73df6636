#include "bodyd/daemon/output.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <string>

namespace bodyd::daemon {

nlohmann::json Output::status() const { return nlohmann::json::object(); }

bool parse_output_spec(std::string_view text, OutputSpec& out, std::string& error) {
  out = OutputSpec{};
  out.text = std::string(text);
  const auto colon = text.find(':');
  const auto query = text.find('?');
  const auto scheme_end = std::min(colon, query);
  out.scheme = std::string(text.substr(0, scheme_end));
  if (out.scheme.empty()) {
    error = "--output \"" + std::string(text) + "\": expected SCHEME:TARGET[?KEY=VALUE&...], e.g. vrchat:127.0.0.1:9000";
    return false;
  }
  if (colon != std::string_view::npos && colon < query)
    out.target = std::string(text.substr(colon + 1, query == std::string_view::npos ? std::string_view::npos : query - colon - 1));
  if (query == std::string_view::npos) return true;
  std::string_view rest = text.substr(query + 1);
  while (!rest.empty()) {
    const auto amp = rest.find('&');
    const std::string_view item = rest.substr(0, amp);
    rest = amp == std::string_view::npos ? std::string_view() : rest.substr(amp + 1);
    const auto eq = item.find('=');
    const std::string key(item.substr(0, eq));
    if (key.empty() || eq == std::string_view::npos) {
      error = "--output \"" + std::string(text) + "\": option \"" + std::string(item) + "\" is not KEY=VALUE";
      return false;
    }
    if (!out.options.emplace(key, std::string(item.substr(eq + 1))).second) {
      error = "--output \"" + std::string(text) + "\": option \"" + key + "\" given twice";
      return false;
    }
  }
  return true;
}

bool take_rate_option(OutputSpec& spec, double& out_rate_hz, std::string& error) {
  out_rate_hz = 0.0;
  const auto it = spec.options.find("rate");
  if (it == spec.options.end()) return true;
  std::size_t used = 0;
  double v = -1.0;
  try {
    v = std::stod(it->second, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != it->second.size() || !std::isfinite(v) || v < 0.0) {
    error = "--output " + spec.text + ": rate \"" + it->second + "\": expected poses per second, a number >= 0 (0: every pose)";
    return false;
  }
  out_rate_hz = v;
  spec.options.erase(it);
  return true;
}

std::string check_options(const OutputSpec& spec, const std::vector<std::string_view>& known) {
  for (const auto& [key, value] : spec.options) {
    bool ok = false;
    for (auto k : known) ok |= k == key;
    if (ok) continue;
    std::string list = "rate";
    for (auto k : known) list += std::string(", ") + std::string(k);
    return "--output " + spec.text + ": unknown option \"" + key + "\" for " + spec.scheme + " outputs (expected " + list +
           "; docs/outputs.md)";
  }
  return {};
}

std::unique_ptr<Output> make_output(const OutputSpec& spec, const OutputEnv& env, std::string& error) {
  std::string schemes;
  for (const OutputKind& kind : output_kinds()) {
    if (kind.scheme == spec.scheme) {
      auto output = kind.factory(spec, env, error);
      if (!output && error.empty()) error = "--output " + spec.text + ": cannot create the output";
      return output;
    }
    schemes += (schemes.empty() ? "" : ", ") + std::string(kind.scheme);
  }
  error = "--output " + spec.text + ": unknown output \"" + spec.scheme + "\" (known: " + schemes + "; docs/outputs.md)";
  return nullptr;
}

bool RateGate::due(std::int64_t t_ns) {
  if (rate_hz_ <= 0.0) return true;
  const auto period_ns = static_cast<std::int64_t>(1e9 / rate_hz_);
  if (next_due_ns_ != INT64_MIN && t_ns + period_ns / 4 < next_due_ns_) return false;
  next_due_ns_ = (next_due_ns_ == INT64_MIN || t_ns - next_due_ns_ > period_ns) ? t_ns + period_ns : next_due_ns_ + period_ns;
  return true;
}

}  // namespace bodyd::daemon
