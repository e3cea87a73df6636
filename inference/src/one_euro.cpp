#include "bodyd/inference/one_euro.h"

#include "bodyd/motion/rotation.h"

#include <fmt/format.h>

#include <cmath>

namespace bodyd {

namespace {
// Smoothing factor of an exponential low-pass with cutoff `cutoff_hz` over `dt_s` (1€ paper, eq. 4).
double alpha(double cutoff_hz, double dt_s) {
  const double tau = 1.0 / (2.0 * M_PI * cutoff_hz);
  return 1.0 / (1.0 + tau / dt_s);
}
}  // namespace

std::string validate(const OneEuroOptions& o) {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  const auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(o.min_cutoff_hz)) return fmt::format("filter min_cutoff_hz must be > 0, not {}", o.min_cutoff_hz);
  if (!positive(o.rot_min_cutoff_hz))
    return fmt::format("filter rot_min_cutoff_hz must be > 0, not {}", o.rot_min_cutoff_hz);
  if (!positive(o.d_cutoff_hz)) return fmt::format("filter d_cutoff_hz must be > 0, not {}", o.d_cutoff_hz);
  if (!non_negative(o.beta_per_m_s)) return fmt::format("filter beta_per_m_s must be >= 0, not {}", o.beta_per_m_s);
  if (!non_negative(o.rot_beta_per_rad_s))
    return fmt::format("filter rot_beta_per_rad_s must be >= 0, not {}", o.rot_beta_per_rad_s);
  if (!positive(o.restart_after_s)) return fmt::format("filter restart_after_s must be > 0, not {}", o.restart_after_s);
  return {};
}

TrackerSample OneEuroFilter::filter(const TrackerSample& in) {
  if (!in.valid) {
    started_ = false;  // a gap: the next valid sample starts over
    return in;
  }
  if (started_ && in.t_ns <= last_t_ns_) return in;
  const double dt_s = started_ ? static_cast<double>(in.t_ns - last_t_ns_) * 1e-9 : 0.0;
  if (!started_ || dt_s > options_.restart_after_s) {
    started_ = true;
    last_t_ns_ = in.t_ns;
    x_ = in.position_m;
    dx_.setZero();
    q_ = in.rotation.normalized();
    w_.setZero();
    return in;
  }
  last_t_ns_ = in.t_ns;
  const double ad = alpha(options_.d_cutoff_hz, dt_s);

  const Vec3 v = (in.position_m - x_) / dt_s;
  dx_ += ad * (v - dx_);
  const double cutoff = options_.min_cutoff_hz + options_.beta_per_m_s * dx_.norm();
  x_ += alpha(cutoff, dt_s) * (in.position_m - x_);

  Quat q_in = in.rotation.normalized();
  if (q_in.dot(q_) < 0.0) q_in.coeffs() = -q_in.coeffs();  // the nearer of q and -q
  // Angular velocity as a vector (world frame), so that noise averages out in its low-pass.
  const Eigen::AngleAxisd step((q_in * q_.conjugate()).normalized());
  const Vec3 w = step.axis() * (step.angle() > M_PI ? step.angle() - 2.0 * M_PI : step.angle()) / dt_s;
  w_ += ad * (w - w_);
  const double rot_cutoff = options_.rot_min_cutoff_hz + options_.rot_beta_per_rad_s * w_.norm();
  q_ = slerp(q_, q_in, alpha(rot_cutoff, dt_s)).normalized();

  TrackerSample out = in;
  out.position_m = x_;
  out.rotation = q_;
  return out;
}

}  // namespace bodyd
