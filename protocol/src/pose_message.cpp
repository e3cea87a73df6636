// Encoding and decoding of the pose and skeleton messages; layout in docs/protocol.md.
#include "bodyd/protocol/pose_message.h"

#include "bytes.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_set>

namespace bodyd::protocol {
namespace {

using detail::Reader;

constexpr double kQuatNormTolerance = 1e-3;

// Field offsets of the pose header (docs/protocol.md, "Pose message").
constexpr std::size_t kPoseOffMagic = 0;
constexpr std::size_t kPoseOffVersion = 4;
constexpr std::size_t kPoseOffJointCount = 6;
constexpr std::size_t kPoseOffSeq = 8;
constexpr std::size_t kPoseOffTime = 16;
constexpr std::size_t kPoseOffPublishTime = 24;
constexpr std::size_t kPoseOffFlags = 32;
constexpr std::size_t kPoseOffSkeletonId = 36;
constexpr std::size_t kPoseOffRootJoint = 40;
constexpr std::size_t kPoseOffFootContact = 42;
constexpr std::size_t kPoseOffRootPosition = 44;
constexpr std::size_t kPoseOffRootHeading = 56;

// Field offsets of the skeleton header and joint entries.
constexpr std::size_t kSkelOffVersion = 4;
constexpr std::size_t kSkelOffJointCount = 6;
constexpr std::size_t kSkelOffId = 8;
constexpr std::size_t kSkelJointOffParent = 0;
constexpr std::size_t kSkelJointOffNameLength = 2;
constexpr std::size_t kSkelJointOffOffset = 4;
constexpr std::size_t kSkelJointOffName = 16;       // version 1
constexpr std::size_t kSkelJointOffRest = 16;       // version 2: rest rotation x, y, z, w
constexpr std::size_t kSkelJointOffNameV2 = 32;     // version 2

std::string hex_bytes(const std::uint8_t* p, std::size_t n) {
  std::string s;
  for (std::size_t i = 0; i < n; ++i) s += fmt::format("{}{:02x}", i ? " " : "", p[i]);
  return s;
}

Status fail(std::string message) { return Status{std::move(message)}; }

bool finite3(const std::array<float, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

// Empty when the quaternion is finite and unit length (within tolerance), else what is wrong.
std::string check_quat(const std::array<float, 4>& q) {
  for (float c : q) {
    if (!std::isfinite(c)) return "is not finite";
  }
  const double norm = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] +
                                double(q[3]) * q[3]);
  if (std::abs(norm - 1.0) > kQuatNormTolerance) {
    return fmt::format("has norm {:.6g}, expected 1 (unit quaternion, within {})", norm, kQuatNormTolerance);
  }
  return {};
}

// Validates a whole pose; shared by the encoder and the decoder so both apply the same rules.
Status check_pose(const PoseMessage& pose, const char* what) {
  if (pose.joints.size() > kMaxJoints) {
    return fail(fmt::format("{}: joint_count {} exceeds the maximum {}", what, pose.joints.size(), kMaxJoints));
  }
  if (pose.root_joint != kNoRootJoint && pose.root_joint >= pose.joints.size()) {
    return fail(fmt::format("{}: root_joint {} is out of range (joint_count {}, 0xFFFF for none)", what,
                            pose.root_joint, pose.joints.size()));
  }
  if (!finite3(pose.root_position_m)) return fail(fmt::format("{}: root_position_m is not finite", what));
  if (!std::isfinite(pose.root_heading_rad)) return fail(fmt::format("{}: root_heading_rad is not finite", what));
  for (std::size_t i = 0; i < pose.joints.size(); ++i) {
    const JointState& j = pose.joints[i];
    if (!finite3(j.position_m)) return fail(fmt::format("{}: joint {} position is not finite", what, i));
    if (std::string q = check_quat(j.rotation_xyzw); !q.empty()) {
      return fail(fmt::format("{}: joint {} rotation {}", what, i, q));
    }
  }
  return {};
}

// Strict UTF-8 (no overlong forms, no surrogates, max U+10FFFF); empty when valid.
std::string check_utf8_name(const std::uint8_t* s, std::size_t n) {
  std::size_t i = 0;
  while (i < n) {
    const std::uint8_t c = s[i];
    if (c < 0x80) {
      if (c < 0x20 || c == 0x7F) return fmt::format("contains control character 0x{:02x} at byte {}", c, i);
      ++i;
      continue;
    }
    std::size_t len = 0;
    std::uint32_t cp = 0;
    std::uint32_t min = 0;
    if ((c & 0xE0) == 0xC0) {
      len = 2, cp = c & 0x1F, min = 0x80;
    } else if ((c & 0xF0) == 0xE0) {
      len = 3, cp = c & 0x0F, min = 0x800;
    } else if ((c & 0xF8) == 0xF0) {
      len = 4, cp = c & 0x07, min = 0x10000;
    } else {
      return fmt::format("is not valid UTF-8 (byte 0x{:02x} at {})", c, i);
    }
    if (len > n - i) return fmt::format("is not valid UTF-8 (sequence cut short at byte {})", i);
    for (std::size_t k = 1; k < len; ++k) {
      const std::uint8_t cc = s[i + k];
      if ((cc & 0xC0) != 0x80) return fmt::format("is not valid UTF-8 (bad continuation byte at {})", i + k);
      cp = (cp << 6) | (cc & 0x3F);
    }
    if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) {
      return fmt::format("is not valid UTF-8 (invalid code point at byte {})", i);
    }
    if (cp >= 0x80 && cp < 0xA0) return fmt::format("contains control character U+{:04X} at byte {}", cp, i);
    i += len;
  }
  return {};
}

std::string printable(const std::string& name) {
  std::string s;
  for (unsigned char c : name) {
    if (c >= 0x20 && c < 0x7F && c != '"' && c != '\\') s += static_cast<char>(c);
    else s += fmt::format("\\x{:02x}", c);
  }
  return s;
}

// The joint table of version 2 when the skeleton has rest rotations, else of version 1.
void append_joint_table(const SkeletonMessage& skeleton, std::vector<std::uint8_t>& out) {
  const bool with_rest = !skeleton.rest_rotations_xyzw.empty();
  for (std::size_t i = 0; i < skeleton.names.size(); ++i) {
    detail::put_i16(out, skeleton.parents[i]);
    detail::put_u16(out, static_cast<std::uint16_t>(skeleton.names[i].size()));
    for (float v : skeleton.offsets_m[i]) detail::put_f32(out, v);
    if (with_rest)
      for (float v : skeleton.rest_rotations_xyzw[i]) detail::put_f32(out, v);
    detail::put_bytes(out, skeleton.names[i].data(), skeleton.names[i].size());
  }
}

std::uint32_t fnv1a(const std::uint8_t* p, std::size_t n) {
  std::uint32_t h = 0x811C9DC5u;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x01000193u;
  }
  return h == 0 ? 1u : h;
}

// What a decoder checks first: the message's whole header is there and starts with its magic.
struct MessageKind {
  const char* name;  // "pose", "skeleton"
  std::size_t header_size;
  const std::array<std::uint8_t, 4>& magic;
};
constexpr MessageKind kPoseKind{"pose", kPoseHeaderSize, kPoseMagic};
constexpr MessageKind kSkeletonKind{"skeleton", kSkeletonHeaderSize, kSkeletonMagic};
static_assert(kPoseOffMagic == 0, "both headers start with their magic");

// Empty when `bytes` holds kind's whole header and starts with its magic; else the error, which
// says when the bytes are the `other` kind of message.
Status check_header(std::span<const std::uint8_t> bytes, const MessageKind& kind, const MessageKind& other) {
  if (bytes.size() < kind.header_size) {
    return fail(fmt::format("{} message: {} bytes is shorter than the {}-byte header", kind.name, bytes.size(),
                            kind.header_size));
  }
  if (std::memcmp(bytes.data(), kind.magic.data(), kind.magic.size()) != 0) {
    const bool is_other = std::memcmp(bytes.data(), other.magic.data(), other.magic.size()) == 0;
    return fail(fmt::format("{} message: wrong magic {} (expected {}, \"{}\"){}", kind.name, hex_bytes(bytes.data(), 4),
                            hex_bytes(kind.magic.data(), kind.magic.size()),
                            std::string(kind.magic.begin(), kind.magic.end()),
                            is_other ? fmt::format("; this is a {} message", other.name) : std::string()));
  }
  return {};
}

}  // namespace

// ---- Pose ----------------------------------------------------------------------------------

Status encode_pose(const PoseMessage& pose, std::vector<std::uint8_t>& out) {
  if (Status s = check_pose(pose, "encode_pose"); !s) return s;
  out.clear();
  out.reserve(kPoseHeaderSize + kPoseJointSize * pose.joints.size());
  detail::put_bytes(out, kPoseMagic.data(), kPoseMagic.size());
  detail::put_u16(out, kPoseVersion);
  detail::put_u16(out, static_cast<std::uint16_t>(pose.joints.size()));
  detail::put_u64(out, pose.seq);
  detail::put_i64(out, pose.t_ns);
  detail::put_i64(out, pose.publish_t_ns);
  detail::put_u32(out, pose.flags);
  detail::put_u32(out, pose.skeleton_id);
  detail::put_u16(out, pose.root_joint);
  detail::put_u8(out, pose.foot_contact);
  detail::put_u8(out, 0);  // reserved
  for (float v : pose.root_position_m) detail::put_f32(out, v);
  detail::put_f32(out, pose.root_heading_rad);
  detail::put_u32(out, 0);  // reserved
  for (const JointState& j : pose.joints) {
    for (float v : j.position_m) detail::put_f32(out, v);
    for (float v : j.rotation_xyzw) detail::put_f32(out, v);
  }
  return {};
}

Status decode_pose(std::span<const std::uint8_t> bytes, PoseMessage& out) {
  if (Status s = check_header(bytes, kPoseKind, kSkeletonKind); !s) return s;
  Reader r(bytes);
  const std::uint16_t version = r.u16(kPoseOffVersion);
  if (version != kPoseVersion) {
    return fail(fmt::format("pose message: unsupported version {} (this decoder reads version {}; "
                            "update the client or the daemon)", version, kPoseVersion));
  }
  const std::size_t n = r.u16(kPoseOffJointCount);
  if (n > kMaxJoints) {
    return fail(fmt::format("pose message: joint_count {} exceeds the maximum {}", n, kMaxJoints));
  }
  const std::size_t expected = kPoseHeaderSize + kPoseJointSize * n;
  if (bytes.size() < expected) {
    return fail(fmt::format("pose message: truncated: {} bytes, joint_count {} needs {}", bytes.size(), n,
                            expected));
  }
  if (bytes.size() > expected) {
    return fail(fmt::format("pose message: {} trailing bytes after {} joints ({} bytes, expected {})",
                            bytes.size() - expected, n, bytes.size(), expected));
  }
  out.seq = r.u64(kPoseOffSeq);
  out.t_ns = r.i64(kPoseOffTime);
  out.publish_t_ns = r.i64(kPoseOffPublishTime);
  out.flags = r.u32(kPoseOffFlags);
  out.skeleton_id = r.u32(kPoseOffSkeletonId);
  out.root_joint = r.u16(kPoseOffRootJoint);
  out.foot_contact = r.u8(kPoseOffFootContact);
  for (std::size_t k = 0; k < 3; ++k) out.root_position_m[k] = r.f32(kPoseOffRootPosition + 4 * k);
  out.root_heading_rad = r.f32(kPoseOffRootHeading);
  out.joints.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t base = kPoseHeaderSize + kPoseJointSize * i;
    for (std::size_t k = 0; k < 3; ++k) out.joints[i].position_m[k] = r.f32(base + 4 * k);
    for (std::size_t k = 0; k < 4; ++k) out.joints[i].rotation_xyzw[k] = r.f32(base + 12 + 4 * k);
  }
  if (r.overrun) return fail("pose message: internal error: read past the end (bug in decode_pose)");
  return check_pose(out, "pose message");
}

// ---- Skeleton --------------------------------------------------------------------------------

Status validate_skeleton(const SkeletonMessage& s) {
  const std::size_t n = s.names.size();
  if (n == 0) return fail("skeleton: no joints");
  if (n > kMaxJoints) return fail(fmt::format("skeleton: {} joints exceeds the maximum {}", n, kMaxJoints));
  if (s.parents.size() != n || s.offsets_m.size() != n) {
    return fail(fmt::format("skeleton: {} names but {} parents and {} offsets", n, s.parents.size(),
                            s.offsets_m.size()));
  }
  if (!s.rest_rotations_xyzw.empty() && s.rest_rotations_xyzw.size() != n) {
    return fail(fmt::format("skeleton: {} names but {} rest rotations (expected {} or none)", n,
                            s.rest_rotations_xyzw.size(), n));
  }
  std::unordered_set<std::string_view> seen;
  for (std::size_t i = 0; i < n; ++i) {
    const std::string& name = s.names[i];
    if (name.empty()) return fail(fmt::format("skeleton: joint {} has an empty name", i));
    if (name.size() > kMaxJointNameBytes) {
      return fail(fmt::format("skeleton: joint {} name is {} bytes long, the maximum is {}", i, name.size(),
                              kMaxJointNameBytes));
    }
    if (std::string e = check_utf8_name(reinterpret_cast<const std::uint8_t*>(name.data()), name.size());
        !e.empty()) {
      return fail(fmt::format("skeleton: joint {} name \"{}\" {}", i, printable(name), e));
    }
    if (!seen.insert(name).second) {
      return fail(fmt::format("skeleton: joint {} name \"{}\" repeats an earlier joint's", i, printable(name)));
    }
    const int parent = s.parents[i];
    if (i == 0 ? parent != -1 : (parent < 0 || parent >= static_cast<int>(i))) {
      return fail(fmt::format("skeleton: joint {} (\"{}\") parent index {} out of range (expected {})", i,
                              printable(name), parent, i == 0 ? "-1 for the root" : fmt::format("0..{}", i - 1)));
    }
    if (!finite3(s.offsets_m[i])) {
      return fail(fmt::format("skeleton: joint {} (\"{}\") offset is not finite", i, printable(name)));
    }
    if (!s.rest_rotations_xyzw.empty()) {
      if (std::string q = check_quat(s.rest_rotations_xyzw[i]); !q.empty())
        return fail(fmt::format("skeleton: joint {} (\"{}\") rest rotation {}", i, printable(name), q));
    }
  }
  return {};
}

std::uint32_t skeleton_id_of(const SkeletonMessage& skeleton) {
  std::vector<std::uint8_t> table;
  const std::size_t n = std::min({skeleton.names.size(), skeleton.parents.size(), skeleton.offsets_m.size()});
  SkeletonMessage trimmed;
  const bool rest_mismatch = !skeleton.rest_rotations_xyzw.empty() && skeleton.rest_rotations_xyzw.size() != n;
  if (n != skeleton.names.size() || n != skeleton.parents.size() || n != skeleton.offsets_m.size() || rest_mismatch) {
    trimmed.names.assign(skeleton.names.begin(), skeleton.names.begin() + static_cast<std::ptrdiff_t>(n));
    trimmed.parents.assign(skeleton.parents.begin(), skeleton.parents.begin() + static_cast<std::ptrdiff_t>(n));
    trimmed.offsets_m.assign(skeleton.offsets_m.begin(),
                             skeleton.offsets_m.begin() + static_cast<std::ptrdiff_t>(n));
    if (skeleton.rest_rotations_xyzw.size() >= n)
      trimmed.rest_rotations_xyzw.assign(skeleton.rest_rotations_xyzw.begin(),
                                         skeleton.rest_rotations_xyzw.begin() + static_cast<std::ptrdiff_t>(n));
    append_joint_table(trimmed, table);
  } else {
    append_joint_table(skeleton, table);
  }
  return fnv1a(table.data(), table.size());
}

Status encode_skeleton(const SkeletonMessage& skeleton, std::vector<std::uint8_t>& out) {
  if (Status s = validate_skeleton(skeleton); !s) return fail("encode_skeleton: " + s.error);
  out.clear();
  detail::put_bytes(out, kSkeletonMagic.data(), kSkeletonMagic.size());
  detail::put_u16(out, skeleton.rest_rotations_xyzw.empty() ? kSkeletonVersionWithoutRest : kSkeletonVersion);
  detail::put_u16(out, static_cast<std::uint16_t>(skeleton.names.size()));
  detail::put_u32(out, 0);  // skeleton_id, filled in below
  detail::put_u32(out, 0);  // reserved
  append_joint_table(skeleton, out);
  const std::uint32_t id = fnv1a(out.data() + kSkeletonHeaderSize, out.size() - kSkeletonHeaderSize);
  for (std::size_t k = 0; k < 4; ++k) out[kSkelOffId + k] = static_cast<std::uint8_t>(id >> (8 * k));
  return {};
}

Status decode_skeleton(std::span<const std::uint8_t> bytes, SkeletonMessage& out) {
  if (Status s = check_header(bytes, kSkeletonKind, kPoseKind); !s) return s;
  Reader r(bytes);
  const std::uint16_t version = r.u16(kSkelOffVersion);
  if (version != kSkeletonVersion && version != kSkeletonVersionWithoutRest) {
    return fail(fmt::format("skeleton message: unsupported version {} (this decoder reads versions {} and {}; "
                            "update the client or the daemon)", version, kSkeletonVersionWithoutRest, kSkeletonVersion));
  }
  const bool with_rest = version == kSkeletonVersion;
  const std::size_t fixed = with_rest ? kSkeletonJointFixedSizeV2 : kSkeletonJointFixedSize;
  const std::size_t name_at = with_rest ? kSkelJointOffNameV2 : kSkelJointOffName;
  const std::size_t n = r.u16(kSkelOffJointCount);
  if (n == 0) return fail("skeleton message: joint_count is 0");
  if (n > kMaxJoints) {
    return fail(fmt::format("skeleton message: joint_count {} exceeds the maximum {}", n, kMaxJoints));
  }
  const std::uint32_t id = r.u32(kSkelOffId);
  out.names.resize(n);
  out.parents.resize(n);
  out.offsets_m.resize(n);
  out.rest_rotations_xyzw.resize(with_rest ? n : 0);
  std::size_t pos = kSkeletonHeaderSize;
  for (std::size_t i = 0; i < n; ++i) {
    if (!r.has(pos, fixed)) {
      return fail(fmt::format("skeleton message: truncated in joint {} of {} (at byte {}, size {})", i, n, pos,
                              bytes.size()));
    }
    out.parents[i] = r.i16(pos + kSkelJointOffParent);
    const std::size_t len = r.u16(pos + kSkelJointOffNameLength);
    for (std::size_t k = 0; k < 3; ++k) out.offsets_m[i][k] = r.f32(pos + kSkelJointOffOffset + 4 * k);
    if (with_rest)
      for (std::size_t k = 0; k < 4; ++k) out.rest_rotations_xyzw[i][k] = r.f32(pos + kSkelJointOffRest + 4 * k);
    if (len == 0 || len > kMaxJointNameBytes) {
      return fail(fmt::format("skeleton message: joint {} name_length {} out of range 1..{}", i, len,
                              kMaxJointNameBytes));
    }
    if (!r.has(pos + name_at, len)) {
      return fail(fmt::format("skeleton message: truncated in joint {} name ({} bytes at byte {}, size {})", i,
                              len, pos + name_at, bytes.size()));
    }
    out.names[i].assign(reinterpret_cast<const char*>(r.at(pos + name_at)), len);
    pos += fixed + len;
  }
  if (pos != bytes.size()) {
    return fail(fmt::format("skeleton message: {} trailing bytes after {} joints", bytes.size() - pos, n));
  }
  if (r.overrun) return fail("skeleton message: internal error: read past the end (bug in decode_skeleton)");
  if (Status s = validate_skeleton(out); !s) return fail("skeleton message: " + s.error.substr(10));
  const std::uint32_t computed = fnv1a(r.at(kSkeletonHeaderSize), bytes.size() - kSkeletonHeaderSize);
  if (id != computed) {
    return fail(fmt::format("skeleton message: skeleton_id 0x{:08x} does not match the joint table's hash "
                            "0x{:08x} (corrupted message or wrong id computation)", id, computed));
  }
  out.skeleton_id = id;
  return {};
}

// ---- Helpers ---------------------------------------------------------------------------------

float heading_rad_from_rotation(const std::array<float, 4>& q) {
  const double x = q[0], y = q[1], z = q[2], w = q[3];
  // Third column of the rotation matrix: the joint's +Z axis in world coordinates.
  const double fx = 2.0 * (x * z + w * y);
  const double fz = 1.0 - 2.0 * (x * x + y * y);
  if (std::abs(fx) < 1e-9 && std::abs(fz) < 1e-9) return 0.0f;
  return static_cast<float>(std::atan2(fx, fz));
}

}  // namespace bodyd::protocol
