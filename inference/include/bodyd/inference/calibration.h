// User-height calibration from the head tracker (docs/daemon.md, "Calibration").
//
// The reconstructors scale by the user's standing head height (Reconstructor::set_user_height).
// Two ways to measure it, both ending in calibrate_from_head_height():
//  - on request: the control socket's {"cmd":"calibrate","from":"head"} takes the head's
//    current height;
//  - automatically: StandingHeightDetector watches the head samples from the start of a session
//    and reports the head's height once it has held still for `still_s` seconds.
// bodyd-eval --body-scale uses the same detector and the same function, so the evaluation
// measures what the daemon does.
#pragma once

#include "bodyd/inference/reconstructor.h"
#include "bodyd/motion/tracker.h"

#include <cstdint>
#include <optional>
#include <string>

namespace bodyd {

// Applies a measured standing head height (metres: the Head joint's height above the floor,
// y = 0) to `reconstructor`. Returns an empty string on success; otherwise what is wrong and
// what to do (a height outside limits::kMinHeadHeightM..kMaxHeadHeightM), and the reconstructor
// is left unchanged. set_user_height() resets the reconstructor's history.
[[nodiscard]] std::string calibrate_from_head_height(Reconstructor& reconstructor, double head_height_m);

struct StandingHeightOptions {
  double still_s = 1.0;             // the head must hold still this long
  double max_travel_m = 0.04;       // "still": every head position of the stretch within this
                                    // distance of the stretch's first one (metres)
  double search_s = 10.0;           // only within this long after the first valid head sample
  double min_height_m = 0.9;        // a still head lower than this is not standing (sitting,
                                    // crouching): keep looking
};

// Finds the first stretch of `still_s` seconds in which the head holds still (from the first
// valid head sample on, within `search_s`), and reports the mean head height over it. Pure: times
// come from the samples. Does not allocate. Not thread-safe: one thread drives one object.
class StandingHeightDetector {
 public:
  explicit StandingHeightDetector(const StandingHeightOptions& options = {}) : options_(options) {}

  // Feeds a sample (other roles and invalid samples are ignored). Returns the standing head
  // height (metres) exactly once: at the sample completing the first still stretch.
  [[nodiscard]] std::optional<double> push(const TrackerSample& sample);
  // Whether the detector has reported a height or given up (search_s passed).
  [[nodiscard]] bool done() const { return done_; }
  [[nodiscard]] std::optional<double> height_m() const { return height_m_; }
  // Starts over (a new session).
  void reset();

 private:
  StandingHeightOptions options_;
  bool started_ = false, done_ = false;
  std::int64_t first_t_ns_ = 0;     // first valid head sample
  std::int64_t anchor_t_ns_ = 0;    // start of the current still stretch
  Vec3 anchor_p_ = Vec3::Zero();
  double sum_y_ = 0.0;
  std::int64_t count_ = 0;
  std::optional<double> height_m_;
};

}  // namespace bodyd
