// TrackerHistory: the recent samples of each tracker role, and the role's pose at any time.
//
// Per role a fixed-capacity ring buffer (allocated once, in the constructor); pushing and
// querying never allocate. Used by the reconstructors (IK baseline, diffusion) to turn
// samples arriving at any rate and in any interleaving of roles into poses at frame times.
//
// Causality: a query names the newest time whose samples it may use (`now_ns`, by default
// the queried time itself); samples later than that are never looked at, even when they
// have already been pushed.
//
// Validity of a queried pose (TrackerSample::valid of the result):
//  - no sample at or before the queried time: invalid (see first_valid() to pad a window);
//  - the queried time lies between two usable samples a (<= t) and b (> t, <= now_ns):
//    both valid and no more than `timeout_ns` apart: interpolated (positions linearly,
//    rotations by slerp); otherwise the sample nearer in time decides (ties: a): invalid
//    if it is invalid or further than `timeout_ns` from the queried time, else its pose;
//  - otherwise the newest sample a <= t is held: valid only if a is valid and
//    t - a.t_ns <= timeout_ns (a tracker that stopped reporting is lost after the timeout).
// Not thread-safe: one thread drives one object.
#pragma once

#include "bodyd/motion/limits.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <cstdint>
#include <vector>

namespace bodyd {

struct TrackerHistoryOptions {
  int capacity = 512;                      // samples kept per role (>= 2)
  std::int64_t timeout_ns = 250'000'000;   // a valid sample older than this no longer counts
  // Valid samples with a position coordinate beyond this (metres, in the units pushed) are
  // refused (see TrackerHistory::push).
  double max_abs_position_m = limits::kMaxAbsPositionM;
};

// The second wall (issue 11): whether a sample may enter a reconstructor's history. Its time
// must be within limits::kMaxAbsTimeNs; a valid sample also needs finite position coordinates
// with |x| <= max_abs_position_m and a finite quaternion with | |q| - 1 | <=
// limits::kQuatNormTolerance. Invalid samples carry no pose, so only their time is checked.
[[nodiscard]] bool tracker_sample_plausible(const TrackerSample& sample,
                                            double max_abs_position_m = limits::kMaxAbsPositionM);

class TrackerHistory {
 public:
  // Capacity < 2, a negative timeout or a max_abs_position_m not > 0 is a bug (BODYD_REQUIRE).
  explicit TrackerHistory(const TrackerHistoryOptions& options = {});

  // Stores a sample. A sample older than its role's newest is ignored and counted
  // (returns false); equal times are kept in arrival order (the later one wins queries).
  // A sample that is not tracker_sample_plausible() (non-finite or absurd values) is refused
  // and counted in refused_count() (returns false), so it can never reach a query.
  bool push(const TrackerSample& sample);
  // Counts a sample the owner refused before pushing it (same counter as push's refusals).
  void note_refused() { ++refused_; }

  // The pose of `role` at `t_ns` from samples with time <= t_ns (see the header comment).
  // `out` is always written: out.t_ns = t_ns, out.role = role; returns out.valid.
  bool query(Role role, std::int64_t t_ns, TrackerSample& out) const;
  // The same, but samples up to `now_ns` (>= t_ns) may be used, so times in the past are
  // interpolated between the samples around them. now_ns < t_ns is treated as t_ns.
  bool query(Role role, std::int64_t t_ns, std::int64_t now_ns, TrackerSample& out) const;

  // The first valid sample of the role since construction or clear() (kept even after the
  // ring overwrote it), or nullptr. For padding a window before the history starts.
  [[nodiscard]] const TrackerSample* first_valid(Role role) const;
  // The newest sample of the role (valid or not), or nullptr when none.
  [[nodiscard]] const TrackerSample* newest(Role role) const;
  // The newest valid sample of the role with time <= t_ns still in the ring, or nullptr.
  [[nodiscard]] const TrackerSample* newest_valid_at_or_before(Role role, std::int64_t t_ns) const;

  [[nodiscard]] int size(Role role) const { return rings_[index(role)].count; }
  [[nodiscard]] int capacity() const { return options_.capacity; }
  [[nodiscard]] const TrackerHistoryOptions& options() const { return options_; }
  // Samples ignored by push() for being older than their role's newest, since construction.
  [[nodiscard]] std::int64_t ignored_count() const { return ignored_; }
  // Samples refused for non-finite or implausible values, since construction (not reset
  // by clear(): a running count for the daemon's status).
  [[nodiscard]] std::int64_t refused_count() const { return refused_; }

  // Forgets every sample (the ignored counter too, not the refused one). Keeps the buffers.
  void clear();

 private:
  struct Ring {
    std::vector<TrackerSample> samples;  // capacity slots
    int head = 0;                        // slot of the oldest sample
    int count = 0;
    bool has_first_valid = false;
    TrackerSample first_valid;
  };
  static std::size_t index(Role role) { return static_cast<std::size_t>(role); }
  // Sample number i (0 = oldest) of a ring.
  [[nodiscard]] const TrackerSample& at(const Ring& ring, int i) const;
  // Number of the newest sample with t_ns <= t, or -1.
  [[nodiscard]] int last_at_or_before(const Ring& ring, std::int64_t t_ns) const;

  TrackerHistoryOptions options_;
  std::array<Ring, kRoleCount> rings_;
  std::int64_t ignored_ = 0;
  std::int64_t refused_ = 0;
};

}  // namespace bodyd
