#include "bodyd/inference/calibration.h"

#include "bodyd/motion/limits.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace bodyd {

std::string calibrate_from_head_height(Reconstructor& reconstructor, double head_height_m) {
  if (!(head_height_m >= limits::kMinHeadHeightM && head_height_m <= limits::kMaxHeadHeightM))
    return fmt::format(
        "the head is at y = {:.3f} m, not a plausible standing head height ({} to {} m): stand up straight on "
        "the floor (y = 0) and retry",
        head_height_m, limits::kMinHeadHeightM, limits::kMaxHeadHeightM);
  reconstructor.set_user_height(head_height_m);
  return {};
}

double standing_height_from_head(double measured_m, const StandingHeightOptions& options) {
  return measured_m / options.stance_ratio;
}

namespace {
// Head samples closer than this to the previous one kept are not kept (bounds the ring at any
// sample rate; the stillness test does not need more than 250 samples a second).
constexpr std::int64_t kMinSpacingNs = 4'000'000;
constexpr double kBinM = 0.001;  // fallback histogram bin
}  // namespace

std::string validate(const StandingHeightOptions& o) {
  const auto positive = [](double x) { return std::isfinite(x) && x > 0.0; };
  if (!positive(o.still_s) || o.still_s > 10.0) return fmt::format("still_s must be in (0, 10] s, not {}", o.still_s);
  if (!positive(o.max_height_range_m)) return fmt::format("max_height_range_m must be > 0, not {}", o.max_height_range_m);
  if (!positive(o.max_floor_travel_m)) return fmt::format("max_floor_travel_m must be > 0, not {}", o.max_floor_travel_m);
  if (!(o.min_height_m >= 0.0 && o.min_height_m < limits::kMaxHeadHeightM))
    return fmt::format("min_height_m must be in [0, {}) m, not {}", limits::kMaxHeadHeightM, o.min_height_m);
  if (!(o.fallback_after_s >= 0.0 && o.fallback_after_s <= 600.0))
    return fmt::format("fallback_after_s must be in [0, 600] s (0: no fallback), not {}", o.fallback_after_s);
  if (!(o.fallback_percentile >= 0.0 && o.fallback_percentile <= 100.0))
    return fmt::format("fallback_percentile must be in [0, 100], not {}", o.fallback_percentile);
  if (!(o.stance_ratio >= 0.8 && o.stance_ratio <= 1.2))
    return fmt::format("stance_ratio must be in [0.8, 1.2], not {}", o.stance_ratio);
  return {};
}

StandingHeightDetector::StandingHeightDetector(const StandingHeightOptions& options) : options_(options) {
  if (std::string e = validate(options_); !e.empty()) throw std::invalid_argument("StandingHeightOptions: " + e);
  ring_.resize(static_cast<std::size_t>(std::ceil(options_.still_s * 1e9 / kMinSpacingNs)) + 2);
  histogram_.assign(static_cast<std::size_t>(std::ceil(limits::kMaxHeadHeightM / kBinM)) + 1, 0);
}

void StandingHeightDetector::reset() {
  started_ = done_ = false;
  ring_head_ = ring_count_ = 0;
  std::fill(histogram_.begin(), histogram_.end(), 0u);
  histogram_count_ = 0;
  result_.reset();
}

// Whether the ring holds a still stretch of still_s seconds ending at t_ns.
bool StandingHeightDetector::window_still(std::int64_t t_ns) const {
  const auto still_ns = static_cast<std::int64_t>(std::llround(options_.still_s * 1e9));
  const std::size_t n = ring_.size();
  // Oldest entry inside the window [t_ns - still_ns, t_ns]: the stretch must span it all.
  const Entry& oldest = ring_[(ring_head_ + n - ring_count_) % n];
  if (t_ns - oldest.t_ns < still_ns - 1000) return false;
  double lo = oldest.p.y(), hi = lo;
  for (std::size_t i = 0; i < ring_count_; ++i) {
    const Entry& e = ring_[(ring_head_ + n - ring_count_ + i) % n];
    lo = std::min(lo, e.p.y());
    hi = std::max(hi, e.p.y());
    const double dx = e.p.x() - oldest.p.x(), dz = e.p.z() - oldest.p.z();
    if (dx * dx + dz * dz > options_.max_floor_travel_m * options_.max_floor_travel_m) return false;
  }
  return hi - lo <= options_.max_height_range_m && lo >= options_.min_height_m;
}

double StandingHeightDetector::fallback_height() const {
  // Nearest rank over the histogram (1 mm bins): the bin's centre.
  const auto rank = static_cast<std::uint64_t>(
      std::max(1.0, std::ceil(options_.fallback_percentile / 100.0 * static_cast<double>(histogram_count_))));
  std::uint64_t seen = 0;
  for (std::size_t b = 0; b < histogram_.size(); ++b) {
    seen += histogram_[b];
    if (seen >= rank) return (static_cast<double>(b) + 0.5) * kBinM;
  }
  return 0.0;
}

std::optional<StandingHeight> StandingHeightDetector::push(const TrackerSample& sample) {
  if (done_ || sample.role != Role::Head || !sample.valid || !sample.position_m.allFinite()) return std::nullopt;
  const std::size_t n = ring_.size();
  if (!started_) {
    started_ = true;
    first_t_ns_ = sample.t_ns;
  } else {
    const Entry& last = ring_[(ring_head_ + n - 1) % n];
    if (sample.t_ns <= last.t_ns) return std::nullopt;
    if (sample.t_ns - last.t_ns < kMinSpacingNs) return std::nullopt;  // (rates above 250 Hz)
  }
  // Keep only the entries of the last still_s (plus the one just before, which starts it).
  ring_[ring_head_] = Entry{sample.t_ns, sample.position_m};
  ring_head_ = (ring_head_ + 1) % n;
  ring_count_ = std::min(ring_count_ + 1, n);
  const auto still_ns = static_cast<std::int64_t>(std::llround(options_.still_s * 1e9));
  while (ring_count_ > 1 && sample.t_ns - ring_[(ring_head_ + n - ring_count_ + 1) % n].t_ns >= still_ns - 1000)
    --ring_count_;
  const double y = sample.position_m.y();
  if (y >= 0.0 && y < limits::kMaxHeadHeightM) {
    ++histogram_[static_cast<std::size_t>(y / kBinM)];
    ++histogram_count_;
  }

  if (window_still(sample.t_ns)) {
    double sum = 0.0;
    for (std::size_t i = 0; i < ring_count_; ++i) sum += ring_[(ring_head_ + n - ring_count_ + i) % n].p.y();
    const double measured = sum / static_cast<double>(ring_count_);
    done_ = true;
    result_ = StandingHeight{standing_height_from_head(measured, options_), measured, false, sample.t_ns};
    return result_;
  }
  if (options_.fallback_after_s > 0.0 &&
      static_cast<double>(sample.t_ns - first_t_ns_) >= options_.fallback_after_s * 1e9 - 1e3) {
    done_ = true;
    const double measured = fallback_height();
    if (measured < options_.min_height_m) return std::nullopt;  // sitting or crouching: no estimate
    result_ = StandingHeight{standing_height_from_head(measured, options_), measured, true, sample.t_ns};
    return result_;
  }
  return std::nullopt;
}

}  // namespace bodyd
