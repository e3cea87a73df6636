#include "bodyd/simulators/sim_option_keys.h"

#include "bodyd/motion/limits.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace bodyd {
namespace {

template <auto Member>
auto& member(SimOptions& o) {
  return o.*Member;
}
template <Role R>
double& role_rate(SimOptions& o) {
  return o.role_rate_hz[static_cast<std::size_t>(R)];
}

constexpr double kMinRateHz = 1e-3;

// clang-format off
const std::array<SimOptionKey, 11> kRows{{
  {"rate_hz", "--rate-hz", "--tracker-rate-hz", &member<&SimOptions::rate_hz>,
   kMinRateHz, limits::kMaxRateHz, false, " Hz", "", "sample rate of every tracker, Hz"},
  {"head_rate_hz", "--head-rate-hz", "", &role_rate<Role::Head>,
   kMinRateHz, limits::kMaxRateHz, true, " Hz", "role_rate_hz[head]",
   "head sample rate, Hz, instead of the rate of every tracker (0: that rate)"},
  {"left_hand_rate_hz", "--left-hand-rate-hz", "", &role_rate<Role::LeftHand>,
   kMinRateHz, limits::kMaxRateHz, true, " Hz", "role_rate_hz[left_hand]",
   "left hand sample rate, Hz, instead of the rate of every tracker (0: that rate)"},
  {"right_hand_rate_hz", "--right-hand-rate-hz", "", &role_rate<Role::RightHand>,
   kMinRateHz, limits::kMaxRateHz, true, " Hz", "role_rate_hz[right_hand]",
   "right hand sample rate, Hz, instead of the rate of every tracker (0: that rate)"},
  {"position_noise_mm", "--noise-mm", "", &member<&SimOptions::position_noise_mm>,
   0.0, 1e4, false, "", "", "position noise: Gaussian std per axis, millimetres"},
  {"rotation_noise_deg", "--noise-deg", "", &member<&SimOptions::rotation_noise_deg>,
   0.0, 180.0, false, "", "", "rotation noise: Gaussian std per axis of a small world-frame rotation, degrees"},
  {"latency_ms", "--latency-ms", "", &member<&SimOptions::latency_ms>,
   0.0, 1e4, false, "", "", "constant latency added to every timestamp, ms"},
  {"jitter_ms", "--jitter-ms", "", &member<&SimOptions::jitter_ms>,
   0.0, 1e3, false, "", "", "timestamp jitter: Gaussian std, ms (clamped below half a sample period)"},
  {"dropout_rate_hz", "--dropout-rate", "", &member<&SimOptions::dropout_rate_hz>,
   0.0, 1e3, false, " episodes per second", "",
   "tracking-loss episodes per hand per second of tracked time (Poisson); the head never drops"},
  {"dropout_mean_ms", "--dropout-mean-ms", "--dropout-ms", &member<&SimOptions::dropout_mean_ms>,
   1e-3, 1e6, false, "", "", "mean duration of a tracking-loss episode (exponential), ms"},
  {"seed", "--seed", "", &member<&SimOptions::seed>, 0.0, 0.0, false, "", "", "random seed"},
}};
// clang-format on

}  // namespace

std::span<const SimOptionKey> sim_option_keys() { return kRows; }

const SimOptionKey* find_sim_option_key(std::string_view key) {
  const auto row = std::ranges::find(kRows, key, &SimOptionKey::key);
  return row == kRows.end() ? nullptr : &*row;
}

std::string SimOptions::validate() const {
  SimOptions& self = const_cast<SimOptions&>(*this);  // the rows' accessors only read here
  for (const SimOptionKey& row : kRows) {
    double& (*const* field)(SimOptions&) = std::get_if<double& (*)(SimOptions&)>(&row.field);
    if (!field) continue;  // an integer: every value of its type is fine
    const double v = (*field)(self);
    if ((row.zero_means_unset && v == 0.0) || (std::isfinite(v) && v >= row.min && v <= row.max)) continue;
    return fmt::format("{} {} must be {}between {} and {}{}", row.message_name.empty() ? row.key : row.message_name, v,
                       row.zero_means_unset ? "0 (use rate_hz) or " : "", row.min, row.max, row.unit);
  }
  return {};
}

}  // namespace bodyd
