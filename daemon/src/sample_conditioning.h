// The daemon's side of sample conditioning: the conditioner itself is shared with the evaluation
// (bodyd/inference/sample_conditioning.h: mounting, offsets, re-centring, the body-tracker rule);
// here are status's re-centring keys and the one cache of the latest valid head sample
// (LatestHead) that the control commands read. Reconstruction thread only.
#pragma once

#include "bodyd/inference/sample_conditioning.h"
#include "bodyd/motion/tracker.h"

#include <nlohmann/json.hpp>

#include <cstdint>

namespace bodyd::daemon {

using bodyd::Recentring;
using bodyd::SampleConditioner;

// status's keys: {"recentred": bool} and, after a recenter, "recentre": {heading_deg, origin_m [x, z]}.
[[nodiscard]] nlohmann::json recentre_status_json(const SampleConditioner& conditioner);

// The latest valid head sample as the reconstructor got it, when it arrived (host monotonic
// time) and the head's speed: the one cache of it, with one freshness rule.
class LatestHead {
 public:
  // A sample newer than this is fresh enough for a command that needs the head now
  // (calibrate --from-head, --pose, reset).
  static constexpr std::int64_t kFreshNs = 2'000'000'000;

  // A valid head sample (conditioned) arrived.
  void update(const TrackerSample& s, std::int64_t arrival_ns);
  // A valid head sample arrived within kFreshNs of now_ns.
  [[nodiscard]] bool fresh(std::int64_t now_ns) const { return arrival_ns_ != 0 && now_ns - arrival_ns_ <= kFreshNs; }
  [[nodiscard]] const TrackerSample& sample() const { return sample_; }
  [[nodiscard]] TrackerSample& sample() { return sample_; }  // re-centring moves it
  // Its speed, smoothed over about 0.2 s (calibrate --from-head refuses a walking head).
  [[nodiscard]] double speed_m_s() const { return speed_m_s_; }

 private:
  TrackerSample sample_;
  std::int64_t arrival_ns_ = 0;
  double speed_m_s_ = 0.0;
};

}  // namespace bodyd::daemon
