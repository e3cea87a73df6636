// The One Euro filter (Casiez, Roussel, Vogel, "1€ Filter: A Simple Speed-based Low-pass Filter
// for Noisy Input in Interactive Systems", CHI 2012), per tracker: an exponential low-pass whose
// cutoff rises with speed, so a still tracker is steady (low cutoff: noise removed) and a fast one
// is followed closely (high cutoff: little lag). Here it smooths the tracker samples the diffusion
// model sees (docs/model.md, "Tracker filter"); the tracked joints are still placed on the raw
// samples (body_solver.h).
//
// Position: cutoff_hz = min_cutoff_hz + beta_per_m_s * |v|, v the speed low-passed at
// d_cutoff_hz; each step x = x_prev + a (x_in - x_prev) with a = 1 / (1 + 1 / (2 pi cutoff dt)).
// Rotation: the same with the angular velocity (rad/s), by slerp from the previous output.
// Time steps come from the samples' timestamps; a tracker that was invalid or silent for more
// than `restart_after_s` starts over at its next valid sample (no smoothing across a gap).
// Pure, no allocation; not thread-safe (one thread drives one object).
#pragma once

#include "bodyd/motion/tracker.h"

#include <array>
#include <cstdint>
#include <string>

namespace bodyd {

struct OneEuroOptions {
  bool enabled = true;
  double min_cutoff_hz = 1.0;        // position cutoff of a still tracker
  double beta_per_m_s = 20.0;        // cutoff increase per m/s of speed (lag at speed -> 1/(2 pi beta) m)
  double rot_min_cutoff_hz = 1.0;    // rotation cutoff of a still tracker
  double rot_beta_per_rad_s = 2.0;   // cutoff increase per rad/s of angular speed
  double d_cutoff_hz = 1.0;          // cutoff of the speed estimate
  double restart_after_s = 0.25;     // a gap longer than this restarts the filter
};
// Empty when usable, otherwise what is wrong (names the field).
[[nodiscard]] std::string validate(const OneEuroOptions& options);

// One tracker's filter.
class OneEuroFilter {
 public:
  explicit OneEuroFilter(const OneEuroOptions& options = {}) : options_(options) {}
  // The filtered sample (time, role and validity unchanged). Invalid samples pass unchanged and
  // mark a gap; samples not later than the previous one pass unchanged.
  [[nodiscard]] TrackerSample filter(const TrackerSample& in);
  void reset() { started_ = false; }

 private:
  OneEuroOptions options_;
  bool started_ = false;
  std::int64_t last_t_ns_ = 0;
  Vec3 x_ = Vec3::Zero(), dx_ = Vec3::Zero();  // filtered position, filtered velocity (m/s)
  Quat q_ = Quat::Identity();
  Vec3 w_ = Vec3::Zero();                      // filtered angular velocity (rad/s, world)
};

// The filters of the three tracker roles.
class TrackerFilter {
 public:
  explicit TrackerFilter(const OneEuroOptions& options = {})
      : filters_{OneEuroFilter(options), OneEuroFilter(options), OneEuroFilter(options)}, enabled_(options.enabled) {}
  [[nodiscard]] TrackerSample filter(const TrackerSample& in) {
    return enabled_ ? filters_[static_cast<size_t>(in.role)].filter(in) : in;
  }
  void reset() {
    for (OneEuroFilter& f : filters_) f.reset();
  }

 private:
  std::array<OneEuroFilter, kRoleCount> filters_;
  bool enabled_ = true;
};

}  // namespace bodyd
