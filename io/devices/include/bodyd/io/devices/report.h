// The bodyd HID tracker report, v1: how a hobbyist device (an ESP32 or RP2040 with an IMU or a
// camera tracker) sends one tracker sample over USB HID or a vendor USB endpoint. The
// specification, with the report descriptor and a worked example, is docs/hid-tracker.md.
//
// One report = one sample of one role, 32 bytes, little-endian:
//
//   off size field
//    0   u8   report_id        0x01 (kTrackerReportId)
//    1   u8   version          1 (kTrackerReportVersion)
//    2   u8   role             0 head, 1 left_hand, 2 right_hand
//    3   u8   flags            bit 0 valid (pose tracked), bit 1 battery low,
//                              bit 2 clock reset (device_time_us restarted); bits 3-7 sent 0, ignored
//    4   u16  sequence         +1 per report the device sends (all roles), wraps 65535 -> 0
//    6   u8   battery_percent  0-100, 255 = unknown
//    7   u8   reserved         sent 0, ignored
//    8   u32  device_time_us   device clock when the pose was measured, wraps after 2^32 us
//   12   i32  px, py, pz       position in 1/10 mm (0.1 mm = 1e-4 m), bodyd world: +Y up
//   24   i16  qx, qy, qz, qw   rotation T_world_joint, Q1.14 (value / 16384), unit length
//
// Decoding and encoding are pure functions (no I/O, no allocation): bytes and size in, a
// struct or an error value out. Every malformed input gives an error, never UB.
#pragma once

#include "bodyd/motion/tracker.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace bodyd::drivers {

inline constexpr std::uint8_t kTrackerReportId = 0x01;
inline constexpr std::uint8_t kTrackerReportVersion = 1;
inline constexpr std::size_t kTrackerReportSize = 32;  // bytes, report ID included
inline constexpr double kTrackerReportPositionUnitM = 1e-4;   // 0.1 mm
inline constexpr double kTrackerReportQuatScale = 16384.0;    // Q1.14
// A valid report's quaternion must satisfy | |q| - 1 | <= this (Q1.14 rounding is < 1e-4);
// it is then renormalised.
inline constexpr double kTrackerReportQuatNormTolerance = 0.02;

// Flag bits (byte 3).
inline constexpr std::uint8_t kReportFlagValid = 0x01;
inline constexpr std::uint8_t kReportFlagBatteryLow = 0x02;
inline constexpr std::uint8_t kReportFlagClockReset = 0x04;

// The HID report descriptor a device declares for this report (vendor usage page 0xFF00,
// one input report, ID 1, 31 opaque bytes after the ID). docs/hid-tracker.md explains it.
inline constexpr std::array<std::uint8_t, 23> kTrackerReportDescriptor{
    0x06, 0x00, 0xFF,  // Usage Page (Vendor Defined 0xFF00)
    0x09, 0x01,        // Usage (0x01: bodyd tracker)
    0xA1, 0x01,        // Collection (Application)
    0x85, 0x01,        //   Report ID (1)
    0x09, 0x02,        //   Usage (0x02: tracker sample)
    0x15, 0x00,        //   Logical Minimum (0)
    0x26, 0xFF, 0x00,  //   Logical Maximum (255)
    0x75, 0x08,        //   Report Size (8 bits)
    0x95, 0x1F,        //   Report Count (31)
    0x81, 0x02,        //   Input (Data, Variable, Absolute)
    0xC0,              // End Collection
};

// A decoded report. Pose fields are meaningful only when `valid`.
struct TrackerReport {
  Role role = Role::Head;
  bool valid = false;
  bool battery_low = false;
  bool clock_reset = false;
  std::uint8_t battery_percent = 255;  // 255: unknown
  std::uint16_t sequence = 0;
  std::uint32_t device_time_us = 0;
  Vec3 position_m = Vec3::Zero();       // multiples of 0.1 mm
  Quat rotation = Quat::Identity();     // unit length after decoding
};

enum class ReportError : std::uint8_t {
  None = 0,
  WrongSize,           // size != kTrackerReportSize
  WrongReportId,       // byte 0 != kTrackerReportId
  UnsupportedVersion,  // byte 1 != kTrackerReportVersion
  BadRole,             // byte 2 > 2
  BadQuaternion,       // valid report whose quaternion is not unit length (within tolerance)
  PositionOutOfRange,  // encoder: a coordinate does not fit in int32 tenths of a millimetre
  NotFinite,           // encoder: NaN or infinite position or rotation
};

// Short name of an error, e.g. "wrong size".
[[nodiscard]] std::string_view report_error_name(ReportError error);
// What is wrong with these bytes, with the offending offset and value, e.g.
// "report of 20 bytes, expected 32 (bodyd tracker report v1)". For logs; allocates.
[[nodiscard]] std::string describe_report_error(ReportError error, const std::uint8_t* data, std::size_t size);

// Decodes one report. `data` may be null only when size is 0. On error `out_report` is unchanged.
[[nodiscard]] ReportError decode_tracker_report(const std::uint8_t* data, std::size_t size,
                                                TrackerReport& out_report);

// Encodes one report (exactly what decode_tracker_report accepts). Position is rounded to
// the nearest 0.1 mm, rotation normalised then rounded to Q1.14. An invalid report has all
// pose bytes zero. On error `out_bytes` is unchanged.
[[nodiscard]] ReportError encode_tracker_report(const TrackerReport& report,
                                                std::array<std::uint8_t, kTrackerReportSize>& out_bytes);

// A decoded pose as a sample stamped with `t_ns`; an invalid one keeps the default position and
// rotation. The one place the device decoders (this report, the Hydra) build their samples.
[[nodiscard]] TrackerSample decoded_sample(std::int64_t t_ns, Role role, bool valid, const Vec3& position_m,
                                           const Quat& rotation);

// The TrackerSample a report carries, stamped with `t_ns` (host monotonic time at read).
[[nodiscard]] TrackerSample sample_from_report(const TrackerReport& report, std::int64_t t_ns);

}  // namespace bodyd::drivers
