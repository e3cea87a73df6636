#include "bodyd/inference/calibration.h"

#include "bodyd/motion/limits.h"

#include <fmt/format.h>

#include <cmath>

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

void StandingHeightDetector::reset() {
  started_ = done_ = false;
  count_ = 0;
  sum_y_ = 0.0;
  height_m_.reset();
}

std::optional<double> StandingHeightDetector::push(const TrackerSample& sample) {
  if (done_ || sample.role != Role::Head || !sample.valid || !sample.position_m.allFinite()) return std::nullopt;
  const auto restart = [&] {
    anchor_t_ns_ = sample.t_ns;
    anchor_p_ = sample.position_m;
    sum_y_ = 0.0;
    count_ = 0;
  };
  if (!started_) {
    started_ = true;
    first_t_ns_ = sample.t_ns;
    restart();
  }
  if (static_cast<double>(sample.t_ns - first_t_ns_) > options_.search_s * 1e9) {
    done_ = true;  // gave up: the user never stood still at the start
    return std::nullopt;
  }
  if ((sample.position_m - anchor_p_).norm() > options_.max_travel_m || sample.position_m.y() < options_.min_height_m)
    restart();
  sum_y_ += sample.position_m.y();
  ++count_;
  if (static_cast<double>(sample.t_ns - anchor_t_ns_) >= options_.still_s * 1e9 - 1e3 &&
      anchor_p_.y() >= options_.min_height_m) {
    done_ = true;
    height_m_ = sum_y_ / static_cast<double>(count_);
    return height_m_;
  }
  return std::nullopt;
}

}  // namespace bodyd
