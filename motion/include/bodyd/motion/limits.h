// Plausible ranges for every number that enters bodyd (spec: docs/tracker-log.md "Limits",
// docs/daemon.md "Limits"). One definition, used by every wall:
//   - the first wall, at each input: the tracker-log reader, config and flags, drivers,
//     BVH loader — a value outside its range is rejected there with file/line/field;
//   - the second wall, inside the reconstructors (inference/src/tracker_history.cpp): a
//     sample that still gets through is refused and counted, never stored in history.
// Shared by the helpers working on issue 11 (REL: reconstructor wall, config, model file;
// HARNESS: tracker-log reader, BVH, fuzz). Change a limit here, and its docs line with it.
#pragma once

#include <cmath>
#include <cstdint>

namespace bodyd::limits {

// Tracker and joint positions, each coordinate, metres. A room-scale tracking volume is
// tens of metres at most; 100 m leaves room for large stages and still keeps squares and
// sums of positions far from float overflow.
inline constexpr double kMaxAbsPositionM = 100.0;

// Device-to-joint offsets (--offset, config "offsets"), each coordinate, metres.
inline constexpr double kMaxAbsOffsetM = 2.0;

// Body height (stature) and standing head height, metres (0 in the config means "the
// model's size"); the same range for both, as the config has always checked.
inline constexpr double kMinUserHeightM = 0.5;
inline constexpr double kMaxUserHeightM = 2.6;
inline constexpr double kMinHeadHeightM = kMinUserHeightM;
inline constexpr double kMaxHeadHeightM = kMaxUserHeightM;

// Rates (pose rate, sample rates), Hz.
inline constexpr double kMaxRateHz = 10000.0;
// A pose rate limit (--rate-hz, an output's ?rate=) is 0 (none) or at least this: one pose in
// 10 s. Its period in ns must fit an int64 (1e9 / rate_hz), which a rate below 1.1e-10 Hz does not.
inline constexpr double kMinPoseRateHz = 0.1;

// Paced replay speed factor (--speed): strictly positive, at most this.
inline constexpr double kMaxReplaySpeed = 1000.0;

// Timestamps, nanoseconds. Times are signed 64-bit; |t| <= 2^62 ns (about 146 years)
// leaves room to add offsets, loop periods and differences without overflow.
inline constexpr std::int64_t kMaxAbsTimeNs = std::int64_t{1} << 62;

// A quaternion's norm must be within this of 1 before it is renormalised.
inline constexpr double kQuatNormTolerance = 1e-3;

[[nodiscard]] inline bool position_plausible(double x_m) {
  return std::isfinite(x_m) && std::fabs(x_m) <= kMaxAbsPositionM;
}
[[nodiscard]] inline bool time_plausible(std::int64_t t_ns) {
  return t_ns >= -kMaxAbsTimeNs && t_ns <= kMaxAbsTimeNs;
}

}  // namespace bodyd::limits
