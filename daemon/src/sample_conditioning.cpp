#include "sample_conditioning.h"

#include "bodyd/inference/features.h"
#include "bodyd/motion/tracker_log.h"

#include <algorithm>
#include <cmath>

namespace bodyd::daemon {

nlohmann::json recentre_status_json(const SampleConditioner& c) {
  if (!c.recentred()) return {{"recentred", false}};
  // The total transform, as "turned by" and "moved by".
  const Vec3 f = c.recentre_rotation() * Vec3::UnitZ();
  const double total_deg = -std::atan2(f.x(), f.z()) * 180.0 / M_PI;
  const Vec3 origin = c.recentre_rotation().conjugate() * (-c.recentre_translation_m());
  return {{"recentred", true}, {"recentre", {{"heading_deg", total_deg}, {"origin_m", {origin.x(), origin.z()}}}}};
}

void LatestHead::update(const TrackerSample& s, std::int64_t arrival_ns) {
  const double dt_s = static_cast<double>(s.t_ns - sample_.t_ns) * 1e-9;
  if (arrival_ns_ != 0 && dt_s > 0.0 && dt_s < 0.5) {
    const double speed = (s.position_m - sample_.position_m).norm() / dt_s;
    const double a = std::min(1.0, dt_s / 0.2);
    speed_m_s_ += a * (speed - speed_m_s_);
  }
  sample_ = s;
  arrival_ns_ = arrival_ns;
}

}  // namespace bodyd::daemon
