#include "stats.h"

#include "bodyd/base/percentile.h"

#include <algorithm>
#include <span>
#include <vector>

namespace bodyd::daemon {

nlohmann::json TimingRing::summary_us() const {
  const std::uint64_t n = count_.load(std::memory_order_acquire);
  const std::size_t m = static_cast<std::size_t>(std::min<std::uint64_t>(n, kSize));
  if (m == 0) return nlohmann::json{{"count", 0}};
  std::vector<std::int64_t> v(m);
  for (std::size_t i = 0; i < m; ++i) v[i] = values_[i].load(std::memory_order_relaxed);
  std::sort(v.begin(), v.end());
  // Nearest rank (bodyd/base/percentile.h); no values is {"count": 0} above.
  auto pct = [&](double p) {
    return static_cast<double>(*percentile_of_sorted(std::span<const std::int64_t>(v), p)) / 1000.0;
  };
  return nlohmann::json{
      {"count", n}, {"window", m}, {"p50", pct(0.5)}, {"p99", pct(0.99)}, {"max", static_cast<double>(v.back()) / 1000.0}};
}

void RoleRateSink::count(const drivers::SourceSample& sample) {
  const auto r = static_cast<std::size_t>(sample.sample.role);
  if (r >= meters_.size()) return;
  const std::int64_t now_ns = sample.arrival_ns;
  std::lock_guard lock(mutex_);
  Meter& m = meters_[r];
  // drivers::RateMeter's rule: a window closes at the first sample a second after it opened, and
  // that sample's time opens the next one.
  if (m.last_ns == 0) m.window_start_ns = now_ns;
  ++m.window_count;
  m.last_ns = now_ns;
  if (const std::int64_t elapsed_ns = now_ns - m.window_start_ns; elapsed_ns >= 1'000'000'000) {
    m.rate_hz = static_cast<double>(m.window_count) * 1e9 / static_cast<double>(elapsed_ns);
    m.window_start_ns = now_ns;
    m.window_count = 0;
  }
}

std::array<double, kRoleCount> RoleRateSink::rate_hz_by_role(std::int64_t now_ns) const {
  std::array<double, kRoleCount> out{};
  std::lock_guard lock(mutex_);
  for (std::size_t r = 0; r < out.size(); ++r)
    out[r] = meters_[r].last_ns != 0 && now_ns - meters_[r].last_ns <= kSilentNs ? meters_[r].rate_hz : 0.0;
  return out;
}

void PipelineStats::to_json(nlohmann::json& j) const {
  j["samples_in"] = samples_in.get();
  // The headset's and controllers' always, a body tracker's once it has sent something.
  nlohmann::json by_role = nlohmann::json::object();
  for (Role r : kRoles)
    if (is_xr_role(r) || role_samples[static_cast<std::size_t>(r)].get() > 0)
      by_role[std::string(role_name(r))] = role_samples[static_cast<std::size_t>(r)].get();
  j["samples_by_role"] = by_role;
  j["body_device_samples_ignored"] = body_device_samples_ignored.get();
  j["frames_out"] = frames_out.get();
  j["frames_not_ready"] = not_ready.get();
  j["frames_skipped_by_rate"] = skipped_by_rate.get();
  j["sends_failed"] = sends_failed.get();
  j["encode_failed"] = encode_failed.get();
  j["samples_refused"] = samples_refused.get();
  j["time_restarts"] = time_restarts.get();
  j["reconstruct_us"] = reconstruct.summary_us();
  j["latency_us"] = latency.summary_us();
}

}  // namespace bodyd::daemon
