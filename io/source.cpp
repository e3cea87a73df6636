#include "bodyd/io/source.h"

namespace bodyd::drivers {

void RateMeter::count(std::int64_t now_ns) {
  constexpr std::int64_t kWindowNs = 1'000'000'000;
  if (window_count_ == 0 && window_start_ns_ == 0) window_start_ns_ = now_ns;
  ++window_count_;
  const std::int64_t elapsed_ns = now_ns - window_start_ns_;
  if (elapsed_ns >= kWindowNs) {
    rate_hz_.store(static_cast<double>(window_count_) * 1e9 / static_cast<double>(elapsed_ns),
                   std::memory_order_relaxed);
    window_start_ns_ = now_ns;
    window_count_ = 0;
  }
}

}  // namespace bodyd::drivers
