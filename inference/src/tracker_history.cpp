#include "bodyd/inference/tracker_history.h"

#include "bodyd/base/require.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

namespace bodyd {

TrackerHistory::TrackerHistory(const TrackerHistoryOptions& options) : options_(options) {
  // No user option reaches these (the reconstructors pass their own): a bad one is a bug.
  BODYD_REQUIRE(options_.capacity >= 2,
                "TrackerHistory: capacity must be at least 2 samples, got " + std::to_string(options_.capacity));
  BODYD_REQUIRE(options_.max_abs_position_m > 0, "TrackerHistory: max_abs_position_m must be > 0");
  BODYD_REQUIRE(options_.timeout_ns >= 0,
                "TrackerHistory: timeout_ns must not be negative, got " + std::to_string(options_.timeout_ns));
  for (Ring& ring : rings_) ring.samples.resize(static_cast<std::size_t>(options_.capacity));
}

const TrackerSample& TrackerHistory::at(const Ring& ring, int i) const {
  return ring.samples[static_cast<std::size_t>((ring.head + i) % options_.capacity)];
}

int TrackerHistory::last_at_or_before(const Ring& ring, std::int64_t t_ns) const {
  // Times within a ring never decrease, so binary search for the first sample later than t.
  int lo = 0, hi = ring.count;
  while (lo < hi) {
    const int mid = lo + (hi - lo) / 2;
    if (at(ring, mid).t_ns <= t_ns)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo - 1;
}

bool tracker_sample_plausible(const TrackerSample& sample, double max_abs_position_m) {
  if (!limits::time_plausible(sample.t_ns)) return false;
  if (!sample.valid) return true;
  for (int k = 0; k < 3; ++k) {
    const double x = sample.position_m[k];
    if (!std::isfinite(x) || std::fabs(x) > max_abs_position_m) return false;
  }
  const auto& c = sample.rotation.coeffs();
  if (!(std::isfinite(c[0]) && std::isfinite(c[1]) && std::isfinite(c[2]) && std::isfinite(c[3]))) return false;
  return std::fabs(sample.rotation.norm() - 1.0) <= limits::kQuatNormTolerance;
}

bool TrackerHistory::push(const TrackerSample& sample) {
  if (!tracker_sample_plausible(sample, options_.max_abs_position_m)) {
    ++refused_;
    return false;
  }
  Ring& ring = rings_[index(sample.role)];
  if (ring.count > 0 && sample.t_ns < at(ring, ring.count - 1).t_ns) {
    ++ignored_;
    return false;
  }
  if (ring.count < options_.capacity) {
    ring.samples[static_cast<std::size_t>((ring.head + ring.count) % options_.capacity)] = sample;
    ++ring.count;
  } else {
    ring.samples[static_cast<std::size_t>(ring.head)] = sample;  // overwrite the oldest
    ring.head = (ring.head + 1) % options_.capacity;
  }
  if (sample.valid && !ring.has_first_valid) {
    ring.first_valid = sample;
    ring.has_first_valid = true;
  }
  return true;
}

bool TrackerHistory::query(Role role, std::int64_t t_ns, TrackerSample& out) const {
  return query(role, t_ns, t_ns, out);
}

bool TrackerHistory::query(Role role, std::int64_t t_ns, std::int64_t now_ns, TrackerSample& out) const {
  now_ns = std::max(now_ns, t_ns);
  out.t_ns = t_ns;
  out.role = role;
  out.valid = false;
  const Ring& ring = rings_[index(role)];
  const int ia = last_at_or_before(ring, t_ns);
  if (ia < 0) return false;
  const TrackerSample& a = at(ring, ia);
  const TrackerSample* b = nullptr;
  if (a.t_ns < t_ns && ia + 1 < ring.count && at(ring, ia + 1).t_ns <= now_ns) b = &at(ring, ia + 1);

  const auto take = [&](const TrackerSample& s) {
    const bool fresh = std::abs(t_ns - s.t_ns) <= options_.timeout_ns;
    if (!s.valid || !fresh) return false;
    out.valid = true;
    out.has_position = s.has_position;
    out.position_m = s.position_m;
    out.rotation = s.rotation;
    return true;
  };

  if (b == nullptr) return take(a);  // exact hit or hold
  if (a.valid && b->valid && b->t_ns - a.t_ns <= options_.timeout_ns) {
    const double u = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b->t_ns - a.t_ns);
    out.valid = true;
    out.has_position = a.has_position && b->has_position;
    out.position_m = a.position_m + u * (b->position_m - a.position_m);
    out.rotation = slerp(a.rotation, b->rotation, u);
    return true;
  }
  return take(t_ns - a.t_ns <= b->t_ns - t_ns ? a : *b);
}

const TrackerSample* TrackerHistory::first_valid(Role role) const {
  const Ring& ring = rings_[index(role)];
  return ring.has_first_valid ? &ring.first_valid : nullptr;
}

const TrackerSample* TrackerHistory::newest(Role role) const {
  const Ring& ring = rings_[index(role)];
  return ring.count > 0 ? &at(ring, ring.count - 1) : nullptr;
}

const TrackerSample* TrackerHistory::newest_valid_at_or_before(Role role, std::int64_t t_ns) const {
  const Ring& ring = rings_[index(role)];
  for (int i = last_at_or_before(ring, t_ns); i >= 0; --i)
    if (at(ring, i).valid) return &at(ring, i);
  return nullptr;
}

void TrackerHistory::clear() {
  for (Ring& ring : rings_) {
    ring.head = 0;
    ring.count = 0;
    ring.has_first_valid = false;
  }
  ignored_ = 0;
}

}  // namespace bodyd
