#include "bodyd/io/devices/report.h"

#include "bodyd/base/little_endian.h"

#include <cmath>
#include <cstdio>
#include <limits>

namespace bodyd::drivers {

namespace {

// Field offsets of the v1 report (docs/hid-tracker.md, "Report layout").
constexpr std::size_t kOffReportId = 0;
constexpr std::size_t kOffVersion = 1;
constexpr std::size_t kOffRole = 2;
constexpr std::size_t kOffFlags = 3;
constexpr std::size_t kOffSequence = 4;
constexpr std::size_t kOffBattery = 6;
constexpr std::size_t kOffDeviceTime = 8;
constexpr std::size_t kOffPosition = 12;  // 3 x i32
constexpr std::size_t kOffRotation = 24;  // 4 x i16, x y z w
static_assert(kOffRotation + 8 == kTrackerReportSize);

}  // namespace

std::string_view report_error_name(ReportError error) {
  switch (error) {
    case ReportError::None: return "no error";
    case ReportError::WrongSize: return "wrong size";
    case ReportError::WrongReportId: return "wrong report ID";
    case ReportError::UnsupportedVersion: return "unsupported version";
    case ReportError::BadRole: return "bad role";
    case ReportError::BadQuaternion: return "quaternion not unit length";
    case ReportError::PositionOutOfRange: return "position out of range";
    case ReportError::NotFinite: return "not finite";
  }
  return "unknown error";
}

std::string describe_report_error(ReportError error, const std::uint8_t* data, std::size_t size) {
  char text[160];
  const bool full = data != nullptr && size >= kTrackerReportSize;
  switch (error) {
    case ReportError::WrongSize:
      std::snprintf(text, sizeof text, "report of %zu bytes, expected %zu (bodyd tracker report v%d)", size,
                    kTrackerReportSize, kTrackerReportVersion);
      return text;
    case ReportError::WrongReportId:
      std::snprintf(text, sizeof text, "byte 0 (report ID) is 0x%02X, expected 0x%02X",
                    data && size ? data[kOffReportId] : 0, kTrackerReportId);
      return text;
    case ReportError::UnsupportedVersion:
      std::snprintf(text, sizeof text, "byte 1 (version) is %d, this bodyd reads version %d",
                    full ? data[kOffVersion] : -1, kTrackerReportVersion);
      return text;
    case ReportError::BadRole:
      std::snprintf(text, sizeof text, "byte 2 (role) is %d, expected 0 (head), 1 (left_hand) or 2 (right_hand)",
                    full ? data[kOffRole] : -1);
      return text;
    case ReportError::BadQuaternion: {
      double n2 = 0.0;
      if (full)
        for (int i = 0; i < 4; ++i) {
          const double c = load_le<std::int16_t>(data + kOffRotation + 2 * i) / kTrackerReportQuatScale;
          n2 += c * c;
        }
      std::snprintf(text, sizeof text, "bytes 24-31 (quaternion, Q1.14) have norm %.4f, expected 1 +- %.2f",
                    std::sqrt(n2), kTrackerReportQuatNormTolerance);
      return text;
    }
    default: return std::string(report_error_name(error));
  }
}

ReportError decode_tracker_report(const std::uint8_t* data, std::size_t size, TrackerReport& out_report) {
  if (data == nullptr || size != kTrackerReportSize) return ReportError::WrongSize;
  if (data[kOffReportId] != kTrackerReportId) return ReportError::WrongReportId;
  if (data[kOffVersion] != kTrackerReportVersion) return ReportError::UnsupportedVersion;
  if (data[kOffRole] >= kXrRoleCount) return ReportError::BadRole;  // docs/hid-tracker.md: head and hands

  TrackerReport r;
  r.role = static_cast<Role>(data[kOffRole]);
  const std::uint8_t flags = data[kOffFlags];
  r.valid = (flags & kReportFlagValid) != 0;
  r.battery_low = (flags & kReportFlagBatteryLow) != 0;
  r.clock_reset = (flags & kReportFlagClockReset) != 0;
  r.sequence = load_le<std::uint16_t>(data + kOffSequence);
  r.battery_percent = data[kOffBattery];
  r.device_time_us = load_le<std::uint32_t>(data + kOffDeviceTime);
  if (r.valid) {
    for (int i = 0; i < 3; ++i)
      r.position_m[i] = load_le<std::int32_t>(data + kOffPosition + 4 * i) * kTrackerReportPositionUnitM;
    const double x = load_le<std::int16_t>(data + kOffRotation + 0) / kTrackerReportQuatScale;
    const double y = load_le<std::int16_t>(data + kOffRotation + 2) / kTrackerReportQuatScale;
    const double z = load_le<std::int16_t>(data + kOffRotation + 4) / kTrackerReportQuatScale;
    const double w = load_le<std::int16_t>(data + kOffRotation + 6) / kTrackerReportQuatScale;
    const double norm = std::sqrt(x * x + y * y + z * z + w * w);
    if (!(std::abs(norm - 1.0) <= kTrackerReportQuatNormTolerance)) return ReportError::BadQuaternion;
    r.rotation = Quat(w / norm, x / norm, y / norm, z / norm);
  }
  out_report = r;
  return ReportError::None;
}

ReportError encode_tracker_report(const TrackerReport& report,
                                  std::array<std::uint8_t, kTrackerReportSize>& out_bytes) {
  std::array<std::uint8_t, kTrackerReportSize> b{};
  const auto role = static_cast<std::uint8_t>(report.role);
  if (role >= kXrRoleCount) return ReportError::BadRole;
  b[kOffReportId] = kTrackerReportId;
  b[kOffVersion] = kTrackerReportVersion;
  b[kOffRole] = role;
  b[kOffFlags] = static_cast<std::uint8_t>((report.valid ? kReportFlagValid : 0) |
                                           (report.battery_low ? kReportFlagBatteryLow : 0) |
                                           (report.clock_reset ? kReportFlagClockReset : 0));
  store_le<std::uint16_t>(&b[kOffSequence], report.sequence);
  b[kOffBattery] = report.battery_percent;
  store_le<std::uint32_t>(&b[kOffDeviceTime], report.device_time_us);
  if (report.valid) {
    const Quat& q = report.rotation;
    if (!report.position_m.allFinite() || !q.coeffs().allFinite()) return ReportError::NotFinite;
    const double norm = q.norm();
    if (!(norm > 0.5)) return ReportError::BadQuaternion;  // no direction to normalise
    for (int i = 0; i < 3; ++i) {
      const double units = std::round(report.position_m[i] / kTrackerReportPositionUnitM);
      if (!(units >= std::numeric_limits<std::int32_t>::min() && units <= std::numeric_limits<std::int32_t>::max()))
        return ReportError::PositionOutOfRange;
      store_le<std::uint32_t>(&b[kOffPosition + 4 * i], static_cast<std::uint32_t>(static_cast<std::int32_t>(units)));
    }
    const double c[4] = {q.x() / norm, q.y() / norm, q.z() / norm, q.w() / norm};
    for (int i = 0; i < 4; ++i) {
      // |c| <= 1, so the rounded value is within [-16384, 16384] and fits in int16.
      const auto v = static_cast<std::int16_t>(std::lround(c[i] * kTrackerReportQuatScale));
      store_le<std::uint16_t>(&b[kOffRotation + 2 * i], static_cast<std::uint16_t>(v));
    }
  }
  out_bytes = b;
  return ReportError::None;
}

TrackerSample decoded_sample(std::int64_t t_ns, Role role, bool valid, const Vec3& position_m, const Quat& rotation) {
  TrackerSample s;
  s.t_ns = t_ns;
  s.role = role;
  s.valid = valid;
  if (valid) {
    s.position_m = position_m;
    s.rotation = rotation;
  }
  return s;
}

TrackerSample sample_from_report(const TrackerReport& report, std::int64_t t_ns) {
  return decoded_sample(t_ns, report.role, report.valid, report.position_m, report.rotation);
}

}  // namespace bodyd::drivers
