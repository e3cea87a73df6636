// The bodyd tracker report decoder and encoder against hand-built bytes (the worked
// example of docs/hid-tracker.md), every malformed case, and round trips.
#include "bodyd/io/devices/report.h"

#include <gtest/gtest.h>

#include <cmath>

namespace bodyd::drivers {
namespace {

using Bytes = std::array<std::uint8_t, kTrackerReportSize>;

// docs/hid-tracker.md, "Worked example": left hand, valid + battery low, sequence 0x1234,
// battery 57 %, device time 0x89ABCDEF us, position (1.2345, -0.05, 1600) m, rotation a
// quarter turn about +Y.
constexpr Bytes kExample{
    0x01, 0x01, 0x01, 0x03,              // report ID, version, role, flags
    0x34, 0x12, 0x39, 0x00,              // sequence, battery, reserved
    0xEF, 0xCD, 0xAB, 0x89,              // device_time_us
    0x39, 0x30, 0x00, 0x00,              // px = 12345
    0x0C, 0xFE, 0xFF, 0xFF,              // py = -500
    0x00, 0x24, 0xF4, 0x00,              // pz = 16000000
    0x00, 0x00, 0x41, 0x2D,              // qx = 0, qy = 11585
    0x00, 0x00, 0x41, 0x2D,              // qz = 0, qw = 11585
};

TEST(TrackerReport, DecodesTheWorkedExample) {
  TrackerReport r;
  ASSERT_EQ(decode_tracker_report(kExample.data(), kExample.size(), r), ReportError::None);
  EXPECT_EQ(r.role, Role::LeftHand);
  EXPECT_TRUE(r.valid);
  EXPECT_TRUE(r.battery_low);
  EXPECT_FALSE(r.clock_reset);
  EXPECT_EQ(r.sequence, 0x1234);
  EXPECT_EQ(r.battery_percent, 57);
  EXPECT_EQ(r.device_time_us, 0x89ABCDEFu);
  EXPECT_NEAR(r.position_m.x(), 1.2345, 1e-12);
  EXPECT_NEAR(r.position_m.y(), -0.05, 1e-12);
  EXPECT_NEAR(r.position_m.z(), 1600.0, 1e-9);
  // A quarter turn about +Y takes +Z to +X.
  const Vec3 z_turned = r.rotation * Vec3::UnitZ();
  EXPECT_NEAR(z_turned.x(), 1.0, 1e-8);
  EXPECT_NEAR(z_turned.z(), 0.0, 1e-8);
  EXPECT_NEAR(r.rotation.norm(), 1.0, 1e-12);

  const TrackerSample s = sample_from_report(r, 42);
  EXPECT_EQ(s.t_ns, 42);
  EXPECT_EQ(s.role, Role::LeftHand);
  EXPECT_TRUE(s.valid);
  EXPECT_EQ(s.position_m, r.position_m);
}

TEST(TrackerReport, EncodesTheWorkedExampleByteForByte) {
  TrackerReport r;
  r.role = Role::LeftHand;
  r.valid = true;
  r.battery_low = true;
  r.sequence = 0x1234;
  r.battery_percent = 57;
  r.device_time_us = 0x89ABCDEF;
  r.position_m = Vec3(1.2345, -0.05, 1600.0);
  r.rotation = Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));
  Bytes out{};
  ASSERT_EQ(encode_tracker_report(r, out), ReportError::None);
  EXPECT_EQ(out, kExample);
}

TEST(TrackerReport, InvalidReportIgnoresPoseBytesAndEncodesZeros) {
  Bytes b = kExample;
  b[3] = 0x00;                     // not valid
  b[24] = b[25] = b[30] = b[31] = 0;  // a zero quaternion is fine when not valid
  TrackerReport r;
  ASSERT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::None);
  EXPECT_FALSE(r.valid);
  EXPECT_EQ(r.position_m, Vec3::Zero());
  EXPECT_FALSE(sample_from_report(r, 0).valid);

  Bytes out{};
  ASSERT_EQ(encode_tracker_report(r, out), ReportError::None);
  for (std::size_t i = 12; i < kTrackerReportSize; ++i) EXPECT_EQ(out[i], 0) << "byte " << i;
}

TEST(TrackerReport, ReservedFlagBitsAndByteAreIgnored) {
  Bytes b = kExample;
  b[3] |= 0xF8;
  b[7] = 0xAA;
  TrackerReport r;
  EXPECT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::None);
  EXPECT_TRUE(r.valid);
}

TEST(TrackerReport, EveryMalformedCaseHasItsError) {
  TrackerReport r;
  r.sequence = 999;  // must stay untouched on error
  for (std::size_t size : {0u, 1u, 31u, 33u, 64u}) {
    std::array<std::uint8_t, 64> big{};
    std::copy(kExample.begin(), kExample.end(), big.begin());
    EXPECT_EQ(decode_tracker_report(big.data(), size, r), ReportError::WrongSize) << size;
  }
  EXPECT_EQ(decode_tracker_report(nullptr, 32, r), ReportError::WrongSize);

  Bytes b = kExample;
  b[0] = 0x02;
  EXPECT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::WrongReportId);
  b = kExample;
  b[1] = 2;
  EXPECT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::UnsupportedVersion);
  b = kExample;
  b[2] = 3;
  EXPECT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::BadRole);
  b[2] = 255;
  EXPECT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::BadRole);
  b = kExample;
  for (int i = 24; i < 32; ++i) b[i] = 0;  // zero quaternion on a valid report
  EXPECT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::BadQuaternion);
  b = kExample;
  b[31] = 0x7F;  // qw = 0x7F41: norm about 2.1
  EXPECT_EQ(decode_tracker_report(b.data(), b.size(), r), ReportError::BadQuaternion);
  EXPECT_EQ(r.sequence, 999);
}

TEST(TrackerReport, ErrorDescriptionsNameTheField) {
  const Bytes b = kExample;
  EXPECT_EQ(describe_report_error(ReportError::WrongSize, b.data(), 20),
            "report of 20 bytes, expected 32 (bodyd tracker report v1)");
  Bytes v = kExample;
  v[1] = 7;
  EXPECT_EQ(describe_report_error(ReportError::UnsupportedVersion, v.data(), v.size()),
            "byte 1 (version) is 7, this bodyd reads version 1");
  Bytes q = kExample;
  for (int i = 24; i < 32; ++i) q[i] = 0;
  EXPECT_NE(describe_report_error(ReportError::BadQuaternion, q.data(), q.size()).find("norm 0.0000"),
            std::string::npos);
  EXPECT_NE(describe_report_error(ReportError::WrongReportId, nullptr, 0).find("report ID"), std::string::npos);
}

TEST(TrackerReport, EncoderRejectsWhatCannotBeSent) {
  TrackerReport r;
  r.valid = true;
  Bytes out{};
  out[0] = 0x77;
  r.position_m = Vec3(250000.0, 0, 0);  // 2.5e9 tenths of a mm > int32
  EXPECT_EQ(encode_tracker_report(r, out), ReportError::PositionOutOfRange);
  r.position_m = Vec3(std::nan(""), 0, 0);
  EXPECT_EQ(encode_tracker_report(r, out), ReportError::NotFinite);
  r.position_m = Vec3::Zero();
  r.rotation = Quat(0, 0, 0, 0);
  EXPECT_EQ(encode_tracker_report(r, out), ReportError::BadQuaternion);
  r.rotation = Quat::Identity();
  r.role = static_cast<Role>(5);
  EXPECT_EQ(encode_tracker_report(r, out), ReportError::BadRole);
  EXPECT_EQ(out[0], 0x77);  // untouched
}

TEST(TrackerReport, RoundTripsWithinQuantisation) {
  std::uint64_t seed = 12345;
  auto rnd = [&seed] {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(seed >> 11) * 0x1.0p-53 * 2.0 - 1.0;
  };
  // Hard cases first: w near zero, half turns, tiny angles, sign of w negative.
  std::vector<Quat> rotations{Quat(0, 1, 0, 0), Quat(0, 0, 0, 1), Quat(1e-6, 0.6, 0.8, 0),
                              Quat(Eigen::AngleAxisd(1e-5, Vec3::UnitX())), Quat(-0.5, 0.5, 0.5, 0.5)};
  for (int i = 0; i < 500; ++i) rotations.push_back(Quat(rnd(), rnd(), rnd(), rnd()).normalized());
  for (const Quat& q : rotations) {
    TrackerReport r;
    r.valid = true;
    r.role = Role::RightHand;
    r.position_m = Vec3(rnd() * 3, rnd() * 3 + 1, rnd() * 3);
    r.rotation = q.normalized();
    Bytes b{};
    ASSERT_EQ(encode_tracker_report(r, b), ReportError::None);
    TrackerReport back;
    ASSERT_EQ(decode_tracker_report(b.data(), b.size(), back), ReportError::None);
    EXPECT_LE((back.position_m - r.position_m).cwiseAbs().maxCoeff(), 0.5e-4 + 1e-12);
    // Q1.14 rounding: at most 0.5/16384 per component, so about 1e-4 rad.
    EXPECT_LT(back.rotation.angularDistance(r.rotation), 2e-4);
  }
}

TEST(TrackerReport, DescriptorDeclaresThirtyOneBytesAfterTheId) {
  // Report Count (0x95) times Report Size (0x75) bits, plus the ID byte, is the report size.
  int count = 0, bits = 0;
  for (std::size_t i = 0; i + 1 < kTrackerReportDescriptor.size(); ++i) {
    if (kTrackerReportDescriptor[i] == 0x95) count = kTrackerReportDescriptor[i + 1];
    if (kTrackerReportDescriptor[i] == 0x75) bits = kTrackerReportDescriptor[i + 1];
  }
  EXPECT_EQ(1 + count * bits / 8, static_cast<int>(kTrackerReportSize));
  EXPECT_EQ(kTrackerReportDescriptor[8], kTrackerReportId);
}

}  // namespace
}  // namespace bodyd::drivers
