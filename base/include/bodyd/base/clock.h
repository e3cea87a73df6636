// The host monotonic clock that every timestamp in bodyd is on (docs/conventions.md): sample
// arrival, publish_t_ns, queue and latency measurements. CLOCK_MONOTONIC through
// std::chrono::steady_clock, in nanoseconds; comparable between processes of one boot.
#pragma once

#include <cstdint>

namespace bodyd {

[[nodiscard]] std::int64_t monotonic_ns();

}  // namespace bodyd
