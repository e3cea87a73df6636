// The one rate limit for a log line that may repeat without end (a rejected packet or report, a
// refused key or serial, an ignored sample): every occurrence is counted where it is reported
// (the status), and the line is logged at the 1st, 2nd, 4th, 8th... occurrence with the count so
// far, so a flood costs a few lines and the log still says how many (docs/architecture.md,
// "Errors").
#pragma once

#include <bit>
#include <cstdint>

namespace bodyd {

// True for the occurrences that are logged: `count` (from 1) a power of two. 0 is not an
// occurrence.
[[nodiscard]] constexpr bool log_occurrence(std::uint64_t count) noexcept { return std::has_single_bit(count); }

}  // namespace bodyd
