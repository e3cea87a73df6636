#include "bodyd/io/output.h"

#include "bodyd/base/spec_options.h"
#include "bodyd/motion/limits.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace bodyd::daemon {

nlohmann::json Output::status() const { return nlohmann::json::object(); }

std::string_view space_name(OutputSpace space) { return space == OutputSpace::User ? "user" : "runtime"; }

bool parse_output_spec(std::string_view text, OutputSpec& out, std::string& error) {
  out = OutputSpec{};
  out.text = std::string(text);
  const auto [head, query] = split_spec_query(text);
  const auto colon = head.find(':');
  out.scheme = std::string(head.substr(0, colon));
  if (out.scheme.empty()) {
    error = "--output \"" + std::string(text) + "\": expected SCHEME:TARGET[?KEY=VALUE&...], e.g. vrchat:127.0.0.1:9000";
    return false;
  }
  if (colon != std::string_view::npos) out.target = std::string(head.substr(colon + 1));
  // The options by the one spec rule (bodyd/base/spec_options.h).
  std::vector<SpecOption> options;
  if (std::string e = parse_spec_options(query, options); !e.empty()) {
    error = "--output \"" + std::string(text) + "\": " + e;
    return false;
  }
  for (SpecOption& o : options) out.options.emplace(std::move(o.key), std::move(o.value));
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
  if (used == 0 || used != it->second.size() || !(v == 0.0 || (v >= limits::kMinPoseRateHz && v <= limits::kMaxRateHz))) {
    error = fmt::format("--output {}: rate \"{}\": expected poses per second, 0 (every pose) or between {} and {}", spec.text,
                        it->second, limits::kMinPoseRateHz, limits::kMaxRateHz);
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

RateGate::RateGate(double rate_hz)
    : rate_hz_(rate_hz > 0.0 ? std::clamp(rate_hz, limits::kMinPoseRateHz, limits::kMaxRateHz) : 0.0) {}

bool RateGate::due(std::int64_t t_ns) {
  if (rate_hz_ <= 0.0) return true;
  const auto period_ns = static_cast<std::int64_t>(1e9 / rate_hz_);
  if (next_due_ns_ != INT64_MIN && t_ns + period_ns / 4 < next_due_ns_) return false;
  next_due_ns_ = (next_due_ns_ == INT64_MIN || t_ns - next_due_ns_ > period_ns) ? t_ns + period_ns : next_due_ns_ + period_ns;
  return true;
}

}  // namespace bodyd::daemon
