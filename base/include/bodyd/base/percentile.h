// Percentiles, one definition for every number bodyd reports as p50 / p90 / p99: the daemon's
// status (reconstruct_us, latency_us), bodyd-bench-latency, bodyd-eval's ms_per_frame_p50/p99 and
// bodyd-sub's statistics line (docs/conventions.md, "Percentiles").
//
// Nearest rank: the percentile p (a fraction in [0, 1]) of n values is the k-th smallest, with
// k = max(1, ceil(p * n)): the smallest value that at least a fraction p of the values do not
// exceed. It is always one of the values (never interpolated); p = 0 gives the minimum, p = 1 the
// maximum. With no values there is no percentile: std::nullopt, which each report writes its own
// documented way. A p outside [0, 1] (or NaN) is a bug in the caller (BODYD_REQUIRE).
#pragma once

#include "bodyd/base/require.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <optional>
#include <span>
#include <vector>

namespace bodyd {

// The 0-based index of the nearest-rank p-percentile in n >= 1 sorted values.
[[nodiscard]] inline std::size_t nearest_rank_index(std::size_t n, double p) {
  BODYD_REQUIRE(p >= 0.0 && p <= 1.0, "a percentile is a fraction in [0, 1]");
  BODYD_REQUIRE(n >= 1, "no percentile of no values");
  const double rank = std::ceil(p * static_cast<double>(n));
  const std::size_t k = rank < 1.0 ? 1 : static_cast<std::size_t>(rank);
  return std::min(k, n) - 1;
}

// The p-percentile of values already sorted ascending; nullopt when empty.
template <typename T>
[[nodiscard]] std::optional<T> percentile_of_sorted(std::span<const T> sorted, double p) {
  if (sorted.empty()) return std::nullopt;
  return sorted[nearest_rank_index(sorted.size(), p)];
}

// The p-percentile of values in any order (reorders them); nullopt when empty.
template <typename T>
[[nodiscard]] std::optional<T> percentile(std::span<T> values, double p) {
  if (values.empty()) return std::nullopt;
  const std::size_t k = nearest_rank_index(values.size(), p);
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}
template <typename T>
[[nodiscard]] std::optional<T> percentile(std::vector<T> values, double p) {
  return percentile(std::span<T>(values), p);
}

}  // namespace bodyd
