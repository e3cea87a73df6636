#include "bodyd/inference/one_euro.h"

#include "bodyd/motion/rotation.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace bodyd {

namespace {
// Smoothing factor of an exponential low-pass with cutoff `cutoff_hz` over `dt_s` (1€ paper, eq. 4).
double alpha(double cutoff_hz, double dt_s) {
  const double tau = 1.0 / (2.0 * M_PI * cutoff_hz);
  return 1.0 / (1.0 + tau / dt_s);
}
}  // namespace

namespace {
// The single-number options and their rule: > 0, or >= 0 where 0 means off (checked in this order).
struct NumberRule {
  std::string_view name;
  double OneEuroOptions::*member;
  bool zero_allowed;
};
constexpr std::array<NumberRule, 10> kNumberRules{{
    {"min_cutoff_hz", &OneEuroOptions::min_cutoff_hz, false},
    {"rot_min_cutoff_hz", &OneEuroOptions::rot_min_cutoff_hz, false},
    {"d_cutoff_hz", &OneEuroOptions::d_cutoff_hz, false},
    {"beta_per_m_s", &OneEuroOptions::beta_per_m_s, true},
    {"rot_beta_per_rad_s", &OneEuroOptions::rot_beta_per_rad_s, true},
    {"head_correction_cutoff_hz", &OneEuroOptions::head_correction_cutoff_hz, false},
    {"hand_reach_slack_m", &OneEuroOptions::hand_reach_slack_m, true},
    {"anchor_cutoff_hz", &OneEuroOptions::anchor_cutoff_hz, true},
    {"arm_soft_zone_m", &OneEuroOptions::arm_soft_zone_m, true},
    {"restart_after_s", &OneEuroOptions::restart_after_s, false},
}};
}  // namespace

std::string validate(const OneEuroOptions& o, std::string_view group) {
  const auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  for (const NumberRule& rule : kNumberRules) {
    const double v = o.*rule.member;
    if (!non_negative(v) || (v == 0.0 && !rule.zero_allowed))
      return fmt::format("{} {} must be {} 0, not {}", group, rule.name, rule.zero_allowed ? ">=" : ">", v);
  }
  if (!non_negative(o.noise_gate_low_mm) || !(std::isfinite(o.noise_gate_high_mm) && o.noise_gate_high_mm > o.noise_gate_low_mm))
    return fmt::format("{} noise gate must be 0 <= noise_gate_low_mm < noise_gate_high_mm, not {} and {}", group,
                       o.noise_gate_low_mm, o.noise_gate_high_mm);
  if (!non_negative(o.rot_noise_gate_low_deg) ||
      !(std::isfinite(o.rot_noise_gate_high_deg) && o.rot_noise_gate_high_deg > o.rot_noise_gate_low_deg))
    return fmt::format(
        "{} rotation noise gate must be 0 <= rot_noise_gate_low_deg < rot_noise_gate_high_deg, not {} and {}", group,
        o.rot_noise_gate_low_deg, o.rot_noise_gate_high_deg);
  if (o.noise_window < 16 || o.noise_window > kMaxNoiseWindow)
    return fmt::format("{} noise_window must be between 16 and {} samples, not {}", group, kMaxNoiseWindow,
                       o.noise_window);
  return {};
}

OneEuroOptions one_euro_options(const BodyFilterOptions& b) {
  OneEuroOptions o;
  o.enabled = b.enabled;
  o.min_cutoff_hz = b.min_cutoff_hz;
  o.beta_per_m_s = b.beta_per_m_s;
  o.d_cutoff_hz = b.d_cutoff_hz;
  o.rot_min_cutoff_hz = b.rot_min_cutoff_hz;
  o.rot_beta_per_rad_s = b.rot_beta_per_rad_s;
  o.noise_gate = false;
  return o;
}

std::string validate(const BodyFilterOptions& options) { return validate(one_euro_options(options), "body_filter"); }

namespace {
// The n-th divided difference of values v at times t (seconds), n = kNoiseOrder, expressed as
// the n-th difference of uniformly spaced samples: n! h^n f[t0..tn], h the mean step. For white
// noise of sigma per axis (uniform steps) each axis has variance C(2n, n) sigma^2; a smooth
// motion's share shrinks as (2 sin(pi f / rate))^n, so a high order separates the two even for
// vigorous motion sampled at 30 Hz (a 3 Hz wave is 30 times further below the noise at n = 6
// than at n = 3).
Vec3 high_difference(const std::array<double, kNoiseOrder + 1>& t, std::array<Vec3, kNoiseOrder + 1> v) {
  for (int level = 1; level <= kNoiseOrder; ++level)
    for (int i = kNoiseOrder; i >= level; --i)
      v[static_cast<size_t>(i)] = (v[static_cast<size_t>(i)] - v[static_cast<size_t>(i - 1)]) /
                                  (t[static_cast<size_t>(i)] - t[static_cast<size_t>(i - level)]);
  const double h = (t[kNoiseOrder] - t[0]) / kNoiseOrder;
  double scale = 1.0;
  for (int k = 1; k <= kNoiseOrder; ++k) scale *= k * h;
  return scale * v[kNoiseOrder];
}

// The gate's gain for a measured noise level.
double gate(double noise, double low, double high) { return std::clamp((noise - low) / (high - low), 0.0, 1.0); }
}  // namespace

void OneEuroFilter::measure_noise(const TrackerSample& in) {
  if (recent_count_ > 0) {
    const std::int64_t prev_ns = recent_[static_cast<size_t>(recent_count_ - 1)].t_ns;
    if (in.t_ns <= prev_ns) return;
    if (static_cast<double>(in.t_ns - prev_ns) * 1e-9 > options_.restart_after_s) recent_count_ = 0;
  }
  if (recent_count_ == kNoiseOrder + 1) {
    for (size_t i = 0; i < kNoiseOrder; ++i) recent_[i] = recent_[i + 1];
    recent_count_ = kNoiseOrder;
  }
  recent_[static_cast<size_t>(recent_count_++)] = in;
  if (recent_count_ <= kNoiseOrder) return;

  std::array<double, kNoiseOrder + 1> t{};
  std::array<Vec3, kNoiseOrder + 1> p, r;
  const Quat mid_inv = recent_[kNoiseOrder / 2].rotation.normalized().conjugate();
  for (size_t i = 0; i <= kNoiseOrder; ++i) {
    t[i] = static_cast<double>(recent_[i].t_ns - recent_[0].t_ns) * 1e-9;
    p[i] = recent_[i].position_m;
    // Rotation vectors relative to the middle sample: for small steps noise adds to them as to
    // positions.
    r[i] = axis_angle_from_quat((recent_[i].rotation.normalized() * mid_inv).normalized());
  }
  const auto window = static_cast<int>(options_.noise_window);
  d3_position_[static_cast<size_t>(noise_next_)] = high_difference(t, p).squaredNorm();
  d3_rotation_[static_cast<size_t>(noise_next_)] = high_difference(t, r).squaredNorm();
  noise_next_ = (noise_next_ + 1) % window;
  noise_count_ = std::min(noise_count_ + 1, window);
  if (noise_count_ < 8) return;

  // The lower quartile of |Dn|^2: for white noise C(2n, n) sigma^2 times the chi-square (3
  // degrees of freedom) quartile 1.2125; motion raises some differences, rarely the lower quartile.
  constexpr double kQuartileToVariance = 1.0 / (924.0 * 1.2125);
  static_assert(kNoiseOrder == 6, "924 = C(12, 6)");
  const auto quartile = [&](const std::array<double, kMaxNoiseWindow>& values) {
    std::copy_n(values.begin(), noise_count_, scratch_.begin());
    const auto k = static_cast<std::ptrdiff_t>((noise_count_ - 1) / 4);
    std::nth_element(scratch_.begin(), scratch_.begin() + k, scratch_.begin() + noise_count_);
    return scratch_[static_cast<size_t>(k)];
  };
  position_noise_mm_ = 1e3 * std::sqrt(quartile(d3_position_) * kQuartileToVariance);
  rotation_noise_deg_ = 180.0 / M_PI * std::sqrt(quartile(d3_rotation_) * kQuartileToVariance);
  position_gain_ = gate(position_noise_mm_, options_.noise_gate_low_mm, options_.noise_gate_high_mm);
  rotation_gain_ = gate(rotation_noise_deg_, options_.rot_noise_gate_low_deg, options_.rot_noise_gate_high_deg);
}

TrackerSample OneEuroFilter::filter(const TrackerSample& in) {
  if (!in.valid) {
    started_ = false;  // a gap: the next valid sample starts over
    recent_count_ = 0;
    return in;
  }
  if (started_ && in.t_ns <= last_t_ns_) return in;
  if (options_.noise_gate) measure_noise(in);
  const double dt_s = started_ ? static_cast<double>(in.t_ns - last_t_ns_) * 1e-9 : 0.0;
  if (!started_ || dt_s > options_.restart_after_s) {
    started_ = true;
    last_t_ns_ = in.t_ns;
    x_ = in.position_m;
    dx_.setZero();
    q_ = in.rotation.normalized();
    w_.setZero();
    first_step_ = true;
    return in;
  }
  last_t_ns_ = in.t_ns;
  // The first step after a (re)start takes the velocity as measured: from zero, the predicted
  // filter would trail a hand that comes back moving, then catch up (a jump of its own).
  const double ad = first_step_ ? 1.0 : alpha(options_.d_cutoff_hz, dt_s);
  first_step_ = false;

  const Vec3 v = (in.position_m - x_) / dt_s;
  dx_ += ad * (v - dx_);
  const double cutoff = options_.min_cutoff_hz + options_.beta_per_m_s * dx_.norm();
  if (options_.predict_velocity) x_ += dx_ * dt_s;
  x_ += alpha(cutoff, dt_s) * (in.position_m - x_);

  Quat q_in = in.rotation.normalized();
  if (q_in.dot(q_) < 0.0) q_in.coeffs() = -q_in.coeffs();  // the nearer of q and -q
  // Angular velocity as a vector (world frame), so that noise averages out in its low-pass.
  const Eigen::AngleAxisd step((q_in * q_.conjugate()).normalized());
  const Vec3 w = step.axis() * (step.angle() > M_PI ? step.angle() - 2.0 * M_PI : step.angle()) / dt_s;
  w_ += ad * (w - w_);
  const double rot_cutoff = options_.rot_min_cutoff_hz + options_.rot_beta_per_rad_s * w_.norm();
  q_ = slerp(q_, q_in, alpha(rot_cutoff, dt_s)).normalized();

  // The noise gate: only as much of the filter as the tracker's noise calls for (all of it
  // without the gate).
  TrackerSample out = in;
  if (!options_.noise_gate) {
    out.position_m = x_;
    out.rotation = q_;
    return out;
  }
  out.position_m = in.position_m + position_gain_ * (x_ - in.position_m);
  out.rotation = slerp(q_in, q_, rotation_gain_).normalized();
  return out;
}

PoseFilter::PoseFilter(const BodyFilterOptions& options, int joint_count, int translated_joint)
    : filters_(static_cast<size_t>(std::max(0, joint_count)), OneEuroFilter(one_euro_options(options))),
      translated_joint_(translated_joint),
      enabled_(options.enabled) {}

void PoseFilter::filter(std::int64_t t_ns, Pose& pose) {
  if (!enabled_) return;
  TrackerSample s;
  s.t_ns = t_ns;
  s.valid = true;
  for (size_t j = 0; j < filters_.size(); ++j) {
    const bool translated = static_cast<int>(j) == translated_joint_;
    s.position_m = translated ? pose.local_translations[j] : Vec3::Zero();
    s.rotation = pose.local_rotations[j];
    const TrackerSample out = filters_[j].filter(s);
    pose.local_rotations[j] = out.rotation;
    if (translated) pose.local_translations[j] = out.position_m;
  }
}

}  // namespace bodyd
