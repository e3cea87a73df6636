// Razer Hydra (Sixense magnetic tracker, USB 1532:0300): report decoder and encoder.
//
// The layout comes from public open-source drivers (VRPN's vrpn_Tracker_RazerHydra and
// Monado's hydra driver; docs/drivers.md gives the details and the conversion). This code
// was written from that description and tested with synthesised reports only: no Hydra
// was available, so the format is unverified against hardware.
//
// Interface 0 streams 52-byte input reports (no report ID) at about 60 Hz once the device
// is in motion-controller mode; interface 1 takes the feature report that switches modes.
//
//   off size field
//    0   7    unknown (ignored)
//    7   u8   sequence counter, +1 per report, wraps
//    8  22    controller 0
//   30  22    controller 1
//   controller block (offsets from its start):
//    0   i16 x3  position x, y, z, millimetres, Hydra frame (origin: the base station)
//    6   i16 x4  rotation w, x, y, z, value / 32768
//   14   u8      buttons
//   15   i16 x2  joystick x, y, value / 32768
//   19   u8      trigger, value / 255
//   20   2       unknown (ignored)
//
// Conversion to bodyd (+Y up, metres): with M the change of basis (x, y, z) -> (x, -z, y),
// position = base_position_m + M p / 1000 and rotation = M q M^T * Rx(pi) (the controller's
// own frame turned half a turn about its x axis so that -Z points along the controller).
#pragma once

#include "bodyd/motion/rotation.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace bodyd::drivers {

inline constexpr std::uint16_t kHydraVendorId = 0x1532;
inline constexpr std::uint16_t kHydraProductId = 0x0300;
inline constexpr int kHydraDataInterface = 0;
inline constexpr int kHydraControlInterface = 1;
inline constexpr std::size_t kHydraReportSize = 52;
inline constexpr std::size_t kHydraFeatureReportSize = 91;  // report ID 0 included
// A controller whose quaternion norm is off by more than this is reported invalid (a
// controller not tracking, e.g. docked or unplugged from the base, reports zeros).
inline constexpr double kHydraQuatNormTolerance = 0.1;

// Feature report 0 (report ID byte first) that switches the Hydra to motion-controller
// mode (byte 9 = 3, byte 89 = 6) or back to gamepad mode (byte 9 = 0, byte 89 = 5).
[[nodiscard]] std::array<std::uint8_t, kHydraFeatureReportSize> hydra_motion_mode_feature_report();
[[nodiscard]] std::array<std::uint8_t, kHydraFeatureReportSize> hydra_gamepad_mode_feature_report();

// Where the Hydra's base station is in the bodyd world, and which controller is which hand.
struct HydraOptions {
  Vec3 base_position_m{0.0, 0.8, 0.0};  // the base on a desk 0.8 m above the floor
  std::array<Role, 2> controller_roles{Role::LeftHand, Role::RightHand};
};

struct HydraController {
  bool valid = false;
  Vec3 position_m = Vec3::Zero();    // bodyd world (base_position_m added)
  Quat rotation = Quat::Identity();  // bodyd world, unit length
  std::uint8_t buttons = 0;
  double joystick_x = 0.0, joystick_y = 0.0;  // [-1, 1)
  double trigger = 0.0;                       // [0, 1]
};

struct HydraReport {
  std::uint8_t sequence = 0;
  std::array<HydraController, 2> controllers;
};

enum class HydraError : std::uint8_t { None = 0, WrongSize };

// Decodes one input report. On error `out_report` is unchanged.
[[nodiscard]] HydraError decode_hydra_report(const std::uint8_t* data, std::size_t size, const HydraOptions& options,
                                             HydraReport& out_report);
// What is wrong, e.g. "Razer Hydra report of 12 bytes, expected 52".
[[nodiscard]] std::string describe_hydra_error(HydraError error, std::size_t size);

// The inverse (for simulated Hydras and tests): positions are rounded to whole millimetres
// and clamped to int16; an invalid controller is all zeros.
[[nodiscard]] std::array<std::uint8_t, kHydraReportSize> encode_hydra_report(const HydraReport& report,
                                                                             const HydraOptions& options);

// The tracker sample of controller `index` (0 or 1), stamped `t_ns`.
[[nodiscard]] TrackerSample hydra_sample(const HydraReport& report, int index, const HydraOptions& options,
                                         std::int64_t t_ns);

}  // namespace bodyd::drivers
