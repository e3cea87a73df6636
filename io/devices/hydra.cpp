#include "bodyd/io/devices/hydra.h"

#include "bodyd/base/little_endian.h"
#include "bodyd/io/devices/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace bodyd::drivers {

namespace {

// Offsets (docs/drivers.md, "Razer Hydra").
constexpr std::size_t kOffSequence = 7;
constexpr std::size_t kOffController[2] = {8, 30};
constexpr std::size_t kOffPosition = 0;   // 3 x i16 mm
constexpr std::size_t kOffRotation = 6;   // 4 x i16, w x y z
constexpr std::size_t kOffButtons = 14;
constexpr std::size_t kOffJoystick = 15;  // 2 x i16
constexpr std::size_t kOffTrigger = 19;
constexpr double kInt16Scale = 32768.0;

// The Hydra frame to bodyd's: M = Rx(+90 deg) maps (x, y, z) to (x, -z, y).
const Quat& hydra_to_bodyd() {
  static const Quat q(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitX()));
  return q;
}
// The controller's own frame correction (half a turn about its x axis).
const Quat& controller_flip() {
  static const Quat q(0.0, 1.0, 0.0, 0.0);  // w x y z: Rx(pi)
  return q;
}

std::array<std::uint8_t, kHydraFeatureReportSize> feature_report(std::uint8_t mode, std::uint8_t tail) {
  std::array<std::uint8_t, kHydraFeatureReportSize> b{};
  b[6] = 0x01;
  b[8] = 0x04;
  b[9] = mode;
  b[89] = tail;
  return b;
}

std::int16_t clamp_i16(double v) {
  return static_cast<std::int16_t>(std::clamp(std::lround(v), -32768L, 32767L));
}

}  // namespace

std::array<std::uint8_t, kHydraFeatureReportSize> hydra_motion_mode_feature_report() {
  return feature_report(0x03, 0x06);
}
std::array<std::uint8_t, kHydraFeatureReportSize> hydra_gamepad_mode_feature_report() {
  return feature_report(0x00, 0x05);
}

HydraError decode_hydra_report(const std::uint8_t* data, std::size_t size, const HydraOptions& options,
                               HydraReport& out_report) {
  if (data == nullptr || size != kHydraReportSize) return HydraError::WrongSize;
  HydraReport r;
  r.sequence = data[kOffSequence];
  for (int c = 0; c < 2; ++c) {
    const std::uint8_t* p = data + kOffController[c];
    HydraController& out = r.controllers[c];
    const Vec3 raw_mm(load_le<std::int16_t>(p + kOffPosition), load_le<std::int16_t>(p + kOffPosition + 2),
                      load_le<std::int16_t>(p + kOffPosition + 4));
    const Quat raw_q(load_le<std::int16_t>(p + kOffRotation) / kInt16Scale, load_le<std::int16_t>(p + kOffRotation + 2) / kInt16Scale,
                     load_le<std::int16_t>(p + kOffRotation + 4) / kInt16Scale, load_le<std::int16_t>(p + kOffRotation + 6) / kInt16Scale);
    const double norm = raw_q.norm();
    out.valid = std::abs(norm - 1.0) <= kHydraQuatNormTolerance;
    if (out.valid) {
      out.position_m = options.base_position_m + hydra_to_bodyd() * (raw_mm * 1e-3);
      const Quat q(raw_q.coeffs() / norm);
      out.rotation = (hydra_to_bodyd() * q * hydra_to_bodyd().conjugate() * controller_flip()).normalized();
    }
    out.buttons = p[kOffButtons];
    out.joystick_x = load_le<std::int16_t>(p + kOffJoystick) / kInt16Scale;
    out.joystick_y = load_le<std::int16_t>(p + kOffJoystick + 2) / kInt16Scale;
    out.trigger = p[kOffTrigger] / 255.0;
  }
  out_report = r;
  return HydraError::None;
}

std::string describe_hydra_error(HydraError error, std::size_t size) {
  if (error == HydraError::None) return "no error";
  char text[120];
  std::snprintf(text, sizeof text, "Razer Hydra report of %zu bytes, expected %zu", size, kHydraReportSize);
  return text;
}

std::array<std::uint8_t, kHydraReportSize> encode_hydra_report(const HydraReport& report,
                                                               const HydraOptions& options) {
  std::array<std::uint8_t, kHydraReportSize> b{};
  b[kOffSequence] = report.sequence;
  for (int c = 0; c < 2; ++c) {
    std::uint8_t* p = b.data() + kOffController[c];
    const HydraController& in = report.controllers[c];
    if (in.valid && in.position_m.allFinite() && in.rotation.coeffs().allFinite() && in.rotation.norm() > 0.5) {
      const Vec3 raw_mm = hydra_to_bodyd().conjugate() * (in.position_m - options.base_position_m) * 1e3;
      for (int i = 0; i < 3; ++i)
        store_le<std::uint16_t>(p + kOffPosition + 2 * i, static_cast<std::uint16_t>(clamp_i16(raw_mm[i])));
      const Quat q = hydra_to_bodyd().conjugate() * (in.rotation.normalized() * controller_flip().conjugate()) *
                     hydra_to_bodyd();
      const double c4[4] = {q.w(), q.x(), q.y(), q.z()};
      // 1.0 * 32768 does not fit; 32767 is the device's largest value.
      for (int i = 0; i < 4; ++i)
        store_le<std::uint16_t>(p + kOffRotation + 2 * i, static_cast<std::uint16_t>(clamp_i16(c4[i] * kInt16Scale)));
    }
    p[kOffButtons] = in.buttons;
    store_le<std::uint16_t>(p + kOffJoystick, static_cast<std::uint16_t>(clamp_i16(in.joystick_x * kInt16Scale)));
    store_le<std::uint16_t>(p + kOffJoystick + 2, static_cast<std::uint16_t>(clamp_i16(in.joystick_y * kInt16Scale)));
    p[kOffTrigger] = static_cast<std::uint8_t>(std::clamp(std::lround(in.trigger * 255.0), 0L, 255L));
  }
  return b;
}

TrackerSample hydra_sample(const HydraReport& report, int index, const HydraOptions& options, std::int64_t t_ns) {
  const HydraController& c = report.controllers[static_cast<std::size_t>(index & 1)];
  return decoded_sample(t_ns, options.controller_roles[static_cast<std::size_t>(index & 1)], c.valid, c.position_m,
                        c.rotation);
}

}  // namespace bodyd::drivers
