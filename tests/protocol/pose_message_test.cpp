// Pose and skeleton messages: golden bytes, round trips, every malformed case, fuzzing.
#include "bodyd/protocol/pose_message.h"
#include "bodyd/protocol/synthetic.h"
#include "bodyd/test/pose_message.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

namespace bodyd::protocol {
namespace {

using ::testing::HasSubstr;
using Bytes = std::vector<std::uint8_t>;

void set_u16(Bytes& b, std::size_t at, std::uint16_t v) {
  b[at] = static_cast<std::uint8_t>(v);
  b[at + 1] = static_cast<std::uint8_t>(v >> 8);
}
void set_u32(Bytes& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}
// `b` with the u16 at `at` made `v`.
Bytes with_u16(Bytes b, std::size_t at, std::uint16_t v) {
  set_u16(b, at, v);
  return b;
}
void set_f32(Bytes& b, std::size_t at, float v) { set_u32(b, at, std::bit_cast<std::uint32_t>(v)); }

Bytes encoded(const PoseMessage& p) {
  Bytes b;
  Status s = encode_pose(p, b);
  EXPECT_TRUE(s.ok()) << s.error;
  return b;
}
Bytes encoded(const SkeletonMessage& sk) {
  Bytes b;
  Status s = encode_skeleton(sk, b);
  EXPECT_TRUE(s.ok()) << s.error;
  return b;
}

std::string pose_error(const Bytes& b) {
  PoseMessage out;
  Status s = decode_pose(b, out);
  return s.ok() ? std::string("(accepted)") : s.error;
}
std::string skeleton_error(const Bytes& b) {
  SkeletonMessage out;
  Status s = decode_skeleton(b, out);
  return s.ok() ? std::string("(accepted)") : s.error;
}

// The FNV-1a of the skeleton's joint table, recomputed here so that tests of later checks
// are not stopped by the id check.
void fix_skeleton_id(Bytes& b) {
  std::uint32_t h = 0x811C9DC5u;
  for (std::size_t i = 16; i < b.size(); ++i) {
    h ^= b[i];
    h *= 0x01000193u;
  }
  set_u32(b, 8, h == 0 ? 1 : h);
}

// ---- Golden bytes: the layout of docs/protocol.md, written out by hand ------------------

// FNV-1a 32 of a skeleton's joint table, computed independently of the library.
std::uint32_t fnv1a(const Bytes& table) {
  std::uint32_t h = 2166136261u;
  for (std::uint8_t c : table) h = (h ^ c) * 16777619u;
  return h;
}

// The skeleton of the golden-bytes tests: "R" at the origin and "Ab" under it at (0, 1, -2).
SkeletonMessage two_joints() {
  SkeletonMessage s;
  s.names = {"R", "Ab"};
  s.parents = {-1, 0};
  s.offsets_m = {{0.0f, 0.0f, 0.0f}, {0.0f, 1.0f, -2.0f}};
  return s;
}

// A skeleton message written out by hand: the header (magic, version, joint count, the
// table's FNV-1a as the id, reserved), then the joint table.
Bytes skeleton_bytes(std::uint8_t version, std::uint8_t joint_count, const Bytes& table) {
  const std::uint32_t h = fnv1a(table);
  Bytes b = {'B', 'D', 'S', 'K', version, 0x00, joint_count, 0x00,
             static_cast<std::uint8_t>(h), static_cast<std::uint8_t>(h >> 8),
             static_cast<std::uint8_t>(h >> 16), static_cast<std::uint8_t>(h >> 24),
             0x00, 0x00, 0x00, 0x00};
  b.insert(b.end(), table.begin(), table.end());
  return b;
}


TEST(PoseMessage, GoldenBytesMatchTheDocumentedLayout) {
  PoseMessage p;
  p.seq = 0x0102030405060708ull;
  p.t_ns = -2;  // two's complement: fe ff ff ff ff ff ff ff
  p.publish_t_ns = 0x1122334455667788ll;
  p.flags = kFlagHeadValid | kFlagRightHandValid | kFlagHeightCalibrated;  // 0x0d
  p.skeleton_id = 0xA1B2C3D4u;
  p.root_joint = 0;
  p.foot_contact = kFootContactRight;
  p.root_position_m = {1.0f, -2.0f, 0.5f};
  p.root_heading_rad = 0.25f;
  p.joints.push_back({{1.0f, 2.0f, 0.5f}, {0.0f, 0.0f, 0.0f, 1.0f}});
  const Bytes expected = {
      'B', 'D', 'P', 'O', 0x01, 0x00, 0x01, 0x00,              // magic, version 1, joint_count 1
      0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01,          // seq
      0xfe, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,          // t_ns = -2
      0x88, 0x77, 0x66, 0x55, 0x44, 0x33, 0x22, 0x11,          // publish_t_ns
      0x0d, 0x00, 0x00, 0x00,                                  // flags
      0xd4, 0xc3, 0xb2, 0xa1,                                  // skeleton_id
      0x00, 0x00, 0x02, 0x00,                                  // root_joint 0, foot_contact right, reserved
      0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0, 0x00, 0x00, 0x00, 0x3f,  // root position 1, -2, 0.5
      0x00, 0x00, 0x80, 0x3e,                                  // heading 0.25
      0x00, 0x00, 0x00, 0x00,                                  // reserved
      0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0x3f,  // joint 0 position 1, 2, 0.5
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // rotation x, y, z = 0
      0x00, 0x00, 0x80, 0x3f};                                 // w = 1
  EXPECT_EQ(encoded(p), expected);
  EXPECT_EQ(expected.size(), kPoseHeaderSize + kPoseJointSize);
}

TEST(SkeletonMessage, GoldenBytesMatchTheDocumentedLayout) {
  SkeletonMessage s = two_joints();
  const Bytes table = {
      0xff, 0xff, 0x01, 0x00,                                            // parent -1, name_length 1
      0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,                                // offset 0, 0, 0
      'R',                                                               // name
      0x00, 0x00, 0x02, 0x00,                                            // parent 0, name_length 2
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0,  // offset 0, 1, -2
      'A', 'b'};
  const std::uint32_t h = fnv1a(table);
  const Bytes expected = skeleton_bytes(1, 2, table);
  EXPECT_EQ(encoded(s), expected);
  EXPECT_EQ(skeleton_id_of(s), h);
}

// Version 2 (a skeleton with rest rotations): each joint entry has the rest rotation between
// the offset and the name. The same skeleton without rest rotations is the version-1 message above.
TEST(SkeletonMessage, Version2GoldenBytes) {
  SkeletonMessage s = two_joints();
  s.rest_rotations_xyzw = {{0.0f, 0.0f, 0.0f, 1.0f}, {0.0f, -1.0f, 0.0f, 0.0f}};
  const Bytes table = {
      0xff, 0xff, 0x01, 0x00,                                            // parent -1, name_length 1
      0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,                                // offset 0, 0, 0
      0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00, 0x80, 0x3f,        // rest rotation 0, 0, 0, 1
      'R',                                                               // name
      0x00, 0x00, 0x02, 0x00,                                            // parent 0, name_length 2
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0,  // offset 0, 1, -2
      0, 0, 0, 0, 0x00, 0x00, 0x80, 0xbf, 0, 0, 0, 0, 0, 0, 0, 0,        // rest rotation 0, -1, 0, 0
      'A', 'b'};
  const std::uint32_t h = fnv1a(table);
  const Bytes expected = skeleton_bytes(2, 2, table);
  EXPECT_EQ(encoded(s), expected);
  EXPECT_EQ(skeleton_id_of(s), h);
  SkeletonMessage back;
  ASSERT_TRUE(decode_skeleton(expected, back).ok());
  EXPECT_EQ(back.rest_rotations_xyzw, s.rest_rotations_xyzw);
  EXPECT_EQ(back.offsets_m, s.offsets_m);
  EXPECT_EQ(back.skeleton_id, h);
  // Decoding version 1 gives no rest rotations, and re-encoding it gives the same bytes.
  s.rest_rotations_xyzw.clear();
  const Bytes v1 = encoded(s);
  EXPECT_EQ(v1[4], 1);
  ASSERT_TRUE(decode_skeleton(v1, back).ok());
  EXPECT_TRUE(back.rest_rotations_xyzw.empty());
  EXPECT_EQ(encoded(back), v1);
}

TEST(SkeletonMessageMalformed, Version2RestRotations) {
  SkeletonMessage s = synthetic_skeleton();
  s.rest_rotations_xyzw.assign(s.names.size(), {0.0f, 0.0f, 0.0f, 1.0f});
  const Bytes good = encoded(s);
  for (std::size_t n = 0; n < good.size(); ++n)
    EXPECT_NE(skeleton_error(Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n))), "(accepted)") << n;
  // Joint 1's rest rotation w (entry 0 is 32 + its name's bytes long) made 2: not unit length.
  Bytes b = good;
  const std::size_t joint1 = 16 + 32 + s.names[0].size();
  set_f32(b, joint1 + 16 + 12, 2.0f);
  fix_skeleton_id(b);
  EXPECT_THAT(skeleton_error(b), HasSubstr("joint 1"));
  EXPECT_THAT(skeleton_error(b), HasSubstr("rest rotation has norm 2"));
  set_f32(b, joint1 + 16, std::numeric_limits<float>::quiet_NaN());
  fix_skeleton_id(b);
  EXPECT_THAT(skeleton_error(b), HasSubstr("rest rotation is not finite"));
  // A version-1 message whose bytes are read as version 2 does not decode.
  b = encoded(synthetic_skeleton());
  set_u16(b, 4, 2);
  EXPECT_NE(skeleton_error(b), "(accepted)");
  // The encoder refuses a rest rotation count that is neither 0 nor the joint count.
  s.rest_rotations_xyzw.pop_back();
  Bytes out;
  EXPECT_THAT(encode_skeleton(s, out).error, HasSubstr("rest rotations"));
}

// ---- Round trips -------------------------------------------------------------------------

TEST(PoseMessage, RoundTripIsBitExact) {
  for (std::uint64_t seq : {0ull, 1ull, 77ull, 123456ull}) {
    const PoseMessage p = synthetic_pose(seq);
    PoseMessage back;
    back.joints.resize(3);  // stale content must be replaced
    ASSERT_TRUE(decode_pose(encoded(p), back).ok());
    EXPECT_TRUE(test::same_pose(p, back));
  }
}

TEST(PoseMessage, RoundTripExtremes) {
  PoseMessage p;
  p.seq = std::numeric_limits<std::uint64_t>::max();
  p.t_ns = std::numeric_limits<std::int64_t>::min();
  p.publish_t_ns = std::numeric_limits<std::int64_t>::max();
  p.flags = 0xFFFFFFFFu;  // unknown bits travel through unchanged
  p.skeleton_id = 0xFFFFFFFFu;
  p.foot_contact = 0xFF;
  p.root_position_m = {-std::numeric_limits<float>::max(), std::numeric_limits<float>::denorm_min(), -0.0f};
  p.root_heading_rad = -3.14159265f;
  p.joints.resize(kMaxJoints);
  for (std::size_t i = 0; i < kMaxJoints; ++i) {
    p.joints[i].position_m = {static_cast<float>(i), -1e30f, 1e-30f};
    // w near zero, rotation by pi.
    p.joints[i].rotation_xyzw = {0.0f, 1.0f, 0.0f, i % 2 ? 0.0f : -0.0f};
  }
  p.root_joint = static_cast<std::uint16_t>(kMaxJoints - 1);
  PoseMessage back;
  ASSERT_TRUE(decode_pose(encoded(p), back).ok());
  EXPECT_TRUE(test::same_pose(p, back));
  EXPECT_TRUE(std::signbit(back.root_position_m[2]));
}

TEST(PoseMessage, ZeroJointsAndNoRoot) {
  PoseMessage p;
  p.seq = 5;
  const Bytes b = encoded(p);
  EXPECT_EQ(b.size(), kPoseHeaderSize);
  PoseMessage back;
  back.joints.resize(4);
  ASSERT_TRUE(decode_pose(b, back).ok());
  EXPECT_TRUE(back.joints.empty());
  EXPECT_EQ(back.root_joint, kNoRootJoint);
}

TEST(PoseMessage, DecodesFromAnUnalignedBuffer) {
  const Bytes b = encoded(synthetic_pose(42));
  for (std::size_t shift = 1; shift < 8; ++shift) {
    Bytes shifted(shift, 0xAA);
    shifted.insert(shifted.end(), b.begin(), b.end());
    PoseMessage back;
    ASSERT_TRUE(decode_pose(std::span(shifted).subspan(shift), back).ok());
    EXPECT_TRUE(test::same_pose(synthetic_pose(42), back));
  }
}

TEST(SkeletonMessage, RoundTrip) {
  const SkeletonMessage s = synthetic_skeleton();
  SkeletonMessage back;
  ASSERT_TRUE(decode_skeleton(encoded(s), back).ok());
  EXPECT_EQ(back.names, s.names);
  EXPECT_EQ(back.parents, s.parents);
  EXPECT_EQ(back.offsets_m, s.offsets_m);
  EXPECT_EQ(back.skeleton_id, s.skeleton_id);
  EXPECT_NE(back.skeleton_id, 0u);
}

TEST(SkeletonMessage, Utf8NamesRoundTrip) {
  SkeletonMessage s;
  s.names = {"Hüfte", "頭", std::string(63, 'x'), "\xF0\x9F\xA6\xB4"};  // 2-, 3-, 4-byte sequences
  s.parents = {-1, 0, 1, 0};
  s.offsets_m = {{0, 0, 0}, {0, 1, 0}, {0, 0.5f, 0}, {0.1f, 0, 0}};
  SkeletonMessage back;
  Status st = decode_skeleton(encoded(s), back);
  ASSERT_TRUE(st.ok()) << st.error;
  EXPECT_EQ(back.names, s.names);
}

TEST(SkeletonMessage, IdChangesWithEveryField) {
  const SkeletonMessage base = synthetic_skeleton();
  EXPECT_EQ(base.skeleton_id, skeleton_id_of(base));
  SkeletonMessage a = base;
  a.names[5] = "Head2";
  SkeletonMessage b = base;
  b.parents[5] = 3;
  SkeletonMessage c = base;
  c.offsets_m[5][1] *= 1.01f;  // a new user height
  EXPECT_NE(skeleton_id_of(a), base.skeleton_id);
  EXPECT_NE(skeleton_id_of(b), base.skeleton_id);
  EXPECT_NE(skeleton_id_of(c), base.skeleton_id);
  // The encoder writes the computed id, not whatever the struct holds.
  SkeletonMessage d = base;
  d.skeleton_id = 12345;
  SkeletonMessage back;
  ASSERT_TRUE(decode_skeleton(encoded(d), back).ok());
  EXPECT_EQ(back.skeleton_id, base.skeleton_id);
}

TEST(Heading, FromRotation) {
  // Identity: +Z forward, heading 0. Yaw by +90 degrees about +Y turns +Z into +X: heading +pi/2.
  EXPECT_FLOAT_EQ(heading_rad_from_rotation({0, 0, 0, 1}), 0.0f);
  const float h = std::sqrt(0.5f);
  EXPECT_NEAR(heading_rad_from_rotation({0, h, 0, h}), M_PI / 2, 1e-6);
  EXPECT_NEAR(heading_rad_from_rotation({0, -h, 0, h}), -M_PI / 2, 1e-6);
  EXPECT_NEAR(std::abs(heading_rad_from_rotation({0, 1, 0, 0})), M_PI, 1e-6);
  // Pitch does not change the heading; pointing straight up gives 0.
  EXPECT_NEAR(heading_rad_from_rotation({0.2588190f, 0, 0, 0.9659258f}), 0.0f, 1e-6);
  EXPECT_FLOAT_EQ(heading_rad_from_rotation({-h, 0, 0, h}), 0.0f);
}

// ---- Malformed pose messages ----------------------------------------------------------------

TEST(PoseMessageMalformed, ShortBuffers) {
  const Bytes good = encoded(synthetic_pose(3));
  EXPECT_THAT(pose_error({}), HasSubstr("shorter than the 64-byte header"));
  EXPECT_THAT(pose_error(Bytes(good.begin(), good.begin() + 63)), HasSubstr("shorter than the 64-byte header"));
  // Every truncation is rejected.
  for (std::size_t n = 0; n < good.size(); ++n) {
    EXPECT_NE(pose_error(Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n))), "(accepted)") << n;
  }
  EXPECT_THAT(pose_error(Bytes(good.begin(), good.end() - 1)), HasSubstr("truncated"));
}

TEST(PoseMessageMalformed, WrongMagic) {
  Bytes b = encoded(synthetic_pose(3));
  b[3] = 'X';
  EXPECT_THAT(pose_error(b), HasSubstr("wrong magic"));
  EXPECT_THAT(pose_error(encoded(synthetic_skeleton())), HasSubstr("this is a skeleton message"));
}

TEST(PoseMessageMalformed, WrongVersion) {
  const Bytes b = encoded(synthetic_pose(3));
  EXPECT_THAT(pose_error(with_u16(b, 4, 2)), HasSubstr("unsupported version 2"));
  EXPECT_THAT(pose_error(with_u16(b, 4, 0)), HasSubstr("unsupported version 0"));
}

TEST(PoseMessageMalformed, WrongCounts) {
  const Bytes b = encoded(synthetic_pose(3));  // 22 joints
  EXPECT_THAT(pose_error(with_u16(b, 6, 23)), HasSubstr("truncated"));
  EXPECT_THAT(pose_error(with_u16(b, 6, 21)), HasSubstr("trailing bytes"));
  EXPECT_THAT(pose_error(with_u16(b, 6, 0xFFFF)), HasSubstr("joint_count 65535 exceeds the maximum 128"));
  // Too many joints even when the size is consistent.
  Bytes big(kPoseHeaderSize + kPoseJointSize * 129, 0);
  std::copy(b.begin(), b.begin() + 64, big.begin());
  set_u16(big, 6, 129);
  EXPECT_THAT(pose_error(big), HasSubstr("exceeds the maximum"));
}

TEST(PoseMessageMalformed, TrailingBytes) {
  Bytes b = encoded(synthetic_pose(3));
  b.push_back(0);
  EXPECT_THAT(pose_error(b), HasSubstr("1 trailing bytes"));
}

TEST(PoseMessageMalformed, RootJointOutOfRange) {
  Bytes b = encoded(synthetic_pose(3));
  set_u16(b, 40, 22);
  EXPECT_THAT(pose_error(b), HasSubstr("root_joint 22 is out of range"));
  set_u16(b, 40, 0xFFFF);
  EXPECT_EQ(pose_error(b), "(accepted)");
}

TEST(PoseMessageMalformed, NonFiniteAndNonUnit) {
  const Bytes good = encoded(synthetic_pose(3));
  Bytes b = good;
  set_f32(b, 64 + 28 * 2 + 4, std::numeric_limits<float>::quiet_NaN());
  EXPECT_THAT(pose_error(b), HasSubstr("joint 2 position is not finite"));
  b = good;
  set_f32(b, 64 + 28 * 5 + 12, std::numeric_limits<float>::infinity());
  EXPECT_THAT(pose_error(b), HasSubstr("joint 5 rotation is not finite"));
  b = good;
  set_f32(b, 64 + 28 * 5 + 24, 2.0f);  // w
  EXPECT_THAT(pose_error(b), HasSubstr("joint 5 rotation has norm"));
  b = good;
  set_f32(b, 48, -std::numeric_limits<float>::infinity());
  EXPECT_THAT(pose_error(b), HasSubstr("root_position_m is not finite"));
  b = good;
  set_f32(b, 56, std::numeric_limits<float>::quiet_NaN());
  EXPECT_THAT(pose_error(b), HasSubstr("root_heading_rad is not finite"));
}

TEST(PoseMessageMalformed, ReservedFieldsAreIgnored) {
  Bytes b = encoded(synthetic_pose(3));
  b[43] = 0x7F;
  set_u32(b, 60, 0xDEADBEEF);
  PoseMessage back;
  ASSERT_TRUE(decode_pose(b, back).ok());
  EXPECT_TRUE(test::same_pose(synthetic_pose(3), back));
}

TEST(PoseMessageEncode, RefusesWhatCannotBeRepresented) {
  std::vector<std::uint8_t> out;
  PoseMessage p = synthetic_pose(1);
  p.joints.resize(kMaxJoints + 1);
  EXPECT_THAT(encode_pose(p, out).error, HasSubstr("exceeds the maximum"));
  p = synthetic_pose(1);
  p.root_joint = 40;
  EXPECT_THAT(encode_pose(p, out).error, HasSubstr("root_joint 40"));
  p = synthetic_pose(1);
  p.joints[0].rotation_xyzw = {0, 0, 0, 0};
  EXPECT_THAT(encode_pose(p, out).error, HasSubstr("joint 0 rotation has norm 0"));
}

// ---- Malformed skeleton messages ----------------------------------------------------------

// Offsets of fields in the encoding of synthetic_skeleton(): joint i's entry.
std::size_t joint_entry(const SkeletonMessage& s, std::size_t i) {
  std::size_t pos = 16;
  for (std::size_t k = 0; k < i; ++k) pos += 16 + s.names[k].size();
  return pos;
}

TEST(SkeletonMessageMalformed, ShortWrongMagicWrongVersion) {
  const Bytes good = encoded(synthetic_skeleton());
  EXPECT_THAT(skeleton_error(Bytes(good.begin(), good.begin() + 15)), HasSubstr("shorter than the 16-byte header"));
  for (std::size_t n = 0; n < good.size(); ++n) {
    EXPECT_NE(skeleton_error(Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n))), "(accepted)") << n;
  }
  Bytes b = good;
  b[0] = 'X';
  EXPECT_THAT(skeleton_error(b), HasSubstr("wrong magic"));
  EXPECT_THAT(skeleton_error(encoded(synthetic_pose(1))), HasSubstr("this is a pose message"));
  b = good;
  set_u16(b, 4, 9);
  EXPECT_THAT(skeleton_error(b), HasSubstr("unsupported version 9"));
}

TEST(SkeletonMessageMalformed, Counts) {
  const SkeletonMessage s = synthetic_skeleton();
  const Bytes good = encoded(s);
  EXPECT_THAT(skeleton_error(with_u16(good, 6, 0)), HasSubstr("joint_count is 0"));
  EXPECT_THAT(skeleton_error(with_u16(good, 6, 129)), HasSubstr("joint_count 129 exceeds the maximum 128"));
  EXPECT_THAT(skeleton_error(with_u16(good, 6, 23)), HasSubstr("truncated in joint 22 of 23"));
  EXPECT_THAT(skeleton_error(with_u16(good, 6, 21)), HasSubstr("trailing bytes after 21 joints"));
  Bytes b = good;
  b.push_back('!');
  EXPECT_THAT(skeleton_error(b), HasSubstr("1 trailing bytes"));
}

TEST(SkeletonMessageMalformed, NameLengths) {
  const SkeletonMessage s = synthetic_skeleton();
  const Bytes good = encoded(s);
  const std::size_t j3 = joint_entry(s, 3);
  Bytes b = good;
  set_u16(b, j3 + 2, 0);
  EXPECT_THAT(skeleton_error(b), HasSubstr("joint 3 name_length 0 out of range 1..63"));
  set_u16(b, j3 + 2, 64);
  EXPECT_THAT(skeleton_error(b), HasSubstr("joint 3 name_length 64 out of range"));
  // Last joint's name running past the end.
  b = good;
  const std::size_t last = joint_entry(s, 21);
  set_u16(b, last + 2, 60);
  EXPECT_THAT(skeleton_error(b), HasSubstr("truncated in joint 21 name"));
}

TEST(SkeletonMessageMalformed, BadNames) {
  const SkeletonMessage s = synthetic_skeleton();
  const std::size_t name5 = joint_entry(s, 5) + 16;  // "Head"
  const auto with_name_bytes = [&](std::initializer_list<std::uint8_t> bytes) {
    Bytes b = encoded(s);
    std::size_t k = 0;
    for (std::uint8_t c : bytes) b[name5 + k++] = c;
    fix_skeleton_id(b);
    return skeleton_error(b);
  };
  EXPECT_THAT(with_name_bytes({0xFF}), HasSubstr("joint 5 name \"\\xffead\" is not valid UTF-8"));
  EXPECT_THAT(with_name_bytes({0xC0, 0x80}), HasSubstr("not valid UTF-8 (invalid code point"));  // overlong NUL
  EXPECT_THAT(with_name_bytes({0xED, 0xA0, 0x80}), HasSubstr("not valid UTF-8"));             // surrogate
  EXPECT_THAT(with_name_bytes({'H', 'e', 'a', 0xE2}), HasSubstr("sequence cut short"));
  EXPECT_THAT(with_name_bytes({'H', 0xC3, 'a'}), HasSubstr("bad continuation byte"));
  EXPECT_THAT(with_name_bytes({'H', 0x00}), HasSubstr("control character 0x00"));
  EXPECT_THAT(with_name_bytes({'\n'}), HasSubstr("control character 0x0a"));
  EXPECT_THAT(with_name_bytes({'N', 'e', 'c', 'k'}), HasSubstr("joint 5 name \"Neck\" repeats"));
}

TEST(SkeletonMessageMalformed, ParentsOutOfRange) {
  const SkeletonMessage s = synthetic_skeleton();
  const auto with_parent = [&](std::size_t joint, std::int16_t parent) {
    Bytes b = encoded(s);
    set_u16(b, joint_entry(s, joint), static_cast<std::uint16_t>(parent));
    fix_skeleton_id(b);
    return skeleton_error(b);
  };
  EXPECT_THAT(with_parent(0, 0), HasSubstr("joint 0 (\"joint_Root\") parent index 0 out of range (expected -1"));
  EXPECT_THAT(with_parent(4, 4), HasSubstr("joint 4 (\"Neck\") parent index 4 out of range (expected 0..3)"));
  EXPECT_THAT(with_parent(4, 21), HasSubstr("parent index 21 out of range"));
  EXPECT_THAT(with_parent(4, 200), HasSubstr("parent index 200 out of range"));
  EXPECT_THAT(with_parent(4, -1), HasSubstr("parent index -1 out of range"));
  EXPECT_THAT(with_parent(4, -7), HasSubstr("parent index -7 out of range"));
  EXPECT_EQ(with_parent(4, 0), "(accepted)");
}

TEST(SkeletonMessageMalformed, NonFiniteOffsetAndWrongId) {
  const SkeletonMessage s = synthetic_skeleton();
  Bytes b = encoded(s);
  set_f32(b, joint_entry(s, 7) + 8, std::numeric_limits<float>::infinity());
  fix_skeleton_id(b);
  EXPECT_THAT(skeleton_error(b), HasSubstr("joint 7 (\"UpperArm_L\") offset is not finite"));
  b = encoded(s);
  b[8] ^= 1;
  EXPECT_THAT(skeleton_error(b), HasSubstr("does not match the joint table's hash"));
  b = encoded(s);
  set_f32(b, joint_entry(s, 7) + 8, 0.123f);  // changed offset, stale id
  EXPECT_THAT(skeleton_error(b), HasSubstr("does not match"));
}

TEST(SkeletonMessageEncode, RefusesInvalidSkeletons) {
  std::vector<std::uint8_t> out;
  SkeletonMessage s = synthetic_skeleton();
  s.parents.pop_back();
  EXPECT_THAT(encode_skeleton(s, out).error, HasSubstr("22 names but 21 parents"));
  s = synthetic_skeleton();
  s.names[3] = std::string(64, 'a');
  EXPECT_THAT(encode_skeleton(s, out).error, HasSubstr("64 bytes long"));
  s = synthetic_skeleton();
  s.names.clear();
  s.parents.clear();
  s.offsets_m.clear();
  EXPECT_THAT(encode_skeleton(s, out).error, HasSubstr("no joints"));
}

// ---- Fuzzing: random and mutated buffers never crash, never read out of bounds ------------
// (Run under -DBODYD_SANITIZE=ON to have out-of-bounds reads reported.)

TEST(ProtocolFuzz, RandomAndMutatedBuffers) {
  std::mt19937_64 rng(20240604);
  const Bytes pose = encoded(synthetic_pose(9));
  const Bytes skel = encoded(synthetic_skeleton());
  PoseMessage pose_out;
  SkeletonMessage skel_out;
  int accepted_mutations = 0;
  for (int iter = 0; iter < 20000; ++iter) {
    Bytes b;
    switch (iter % 4) {
      case 0: {  // pure noise, sometimes with a valid header prefix
        b.resize(rng() % 300);
        for (auto& c : b) c = static_cast<std::uint8_t>(rng());
        if (b.size() >= 8 && rng() % 2) {
          const Bytes& src = rng() % 2 ? pose : skel;
          std::copy(src.begin(), src.begin() + 8, b.begin());
        }
        break;
      }
      case 1:  // a valid pose with 1-4 random bytes changed
      case 2: {  // a valid skeleton with 1-4 random bytes changed
        b = iter % 4 == 1 ? pose : skel;
        const int flips = 1 + static_cast<int>(rng() % 4);
        for (int k = 0; k < flips; ++k) b[rng() % b.size()] = static_cast<std::uint8_t>(rng());
        break;
      }
      default: {  // truncated or extended copies, in an exactly sized heap buffer
        b = rng() % 2 ? pose : skel;
        if (rng() % 2) b.resize(rng() % b.size());
        else b.resize(b.size() + 1 + rng() % 16, static_cast<std::uint8_t>(rng()));
        break;
      }
    }
    b.shrink_to_fit();
    const bool pose_ok = decode_pose(b, pose_out).ok();
    const bool skel_ok = decode_skeleton(b, skel_out).ok();
    EXPECT_FALSE(pose_ok && skel_ok);
    if (iter % 4 == 3) {
      EXPECT_FALSE(pose_ok || skel_ok) << "a truncated or extended message was accepted";
    }
    if (pose_ok) {  // whatever is accepted re-encodes to the same bytes, reserved fields aside
      Bytes again;
      ASSERT_TRUE(encode_pose(pose_out, again).ok());
      b[43] = 0;
      std::fill(b.begin() + 60, b.begin() + 64, 0);
      EXPECT_EQ(again, b);
      ++accepted_mutations;
    }
    if (skel_ok) {
      Bytes again;
      ASSERT_TRUE(encode_skeleton(skel_out, again).ok());
      std::fill(b.begin() + 12, b.begin() + 16, 0);
      EXPECT_EQ(again, b);
    }
  }
  // Byte flips in float fields give valid messages often; the loop must exercise that path.
  EXPECT_GT(accepted_mutations, 100);
}

}  // namespace
}  // namespace bodyd::protocol
