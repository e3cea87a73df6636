// The bodyd wire protocol: the messages of the pose stream, as plain structs, and their
// encoding and decoding as pure functions (bytes in, struct out; struct in, bytes out).
//
// The byte layout is specified in docs/protocol.md; this header and that document must
// agree. Everything on the wire is little-endian; floats are IEEE-754 binary32. The
// decoder never assumes alignment (it copies fields out with memcpy) and never reads
// past the buffer it is given; every malformed input gives a DecodeStatus naming the
// field that is wrong.
//
// This library knows nothing of ZeroMQ or of the model: the daemon and the clients send
// and receive the bytes; here they are only produced and checked.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::protocol {

// ---- Constants -----------------------------------------------------------------------

// Each message kind carries its own version after its magic. The pose message is at version 1;
// the skeleton message at version 2 (version 1 had no rest rotations; it is still decoded, and
// written for a skeleton without rest rotations, so old recordings re-encode bit for bit).
inline constexpr std::uint16_t kPoseVersion = 1;
inline constexpr std::uint16_t kSkeletonVersion = 2;
inline constexpr std::uint16_t kSkeletonVersionWithoutRest = 1;
inline constexpr std::uint16_t kProtocolVersion = kPoseVersion;  // the version of protocol 1's pose message

// Topic frames (the first frame of each multipart message; subscribe by these prefixes).
inline constexpr std::string_view kPoseTopic = "pose";
inline constexpr std::string_view kSkeletonTopic = "skeleton";

// Magic numbers: the first four bytes of each message frame, as ASCII.
inline constexpr std::array<std::uint8_t, 4> kPoseMagic{'B', 'D', 'P', 'O'};
inline constexpr std::array<std::uint8_t, 4> kSkeletonMagic{'B', 'D', 'S', 'K'};

// Sizes in bytes (see docs/protocol.md for the field offsets).
inline constexpr std::size_t kPoseHeaderSize = 64;
inline constexpr std::size_t kPoseJointSize = 28;      // position xyz + rotation xyzw, float32
inline constexpr std::size_t kSkeletonHeaderSize = 16;
inline constexpr std::size_t kSkeletonJointFixedSize = 16;    // v1: parent i16, name length u16, offset xyz
inline constexpr std::size_t kSkeletonJointFixedSizeV2 = 32;  // v2: ... then rest rotation xyzw

// Limits a decoder enforces (a message beyond them is malformed).
inline constexpr std::size_t kMaxJoints = 128;
inline constexpr std::size_t kMaxJointNameBytes = 63;

// Default endpoints of the daemon (configurable there).
inline constexpr std::string_view kDefaultPoseEndpoint = "ipc:///tmp/bodyd/pose";
inline constexpr std::string_view kDefaultControlEndpoint = "ipc:///tmp/bodyd/control";

// ---- Pose message --------------------------------------------------------------------

// Bits of PoseMessage::flags. Bits not named here are sent as 0 and ignored on receipt.
enum PoseFlags : std::uint32_t {
  kFlagHeadValid = 1u << 0,        // the head tracker was tracking at t_ns
  kFlagLeftHandValid = 1u << 1,    // the left-hand tracker was tracking at t_ns
  kFlagRightHandValid = 1u << 2,   // the right-hand tracker was tracking at t_ns
  kFlagHeightCalibrated = 1u << 3, // the user's height was calibrated (else the model's default height)
  kFlagOffsetsCalibrated = 1u << 4,  // per-device tracker offsets were configured (else defaults)
};
inline constexpr std::uint32_t kKnownPoseFlags = 0x1Fu;

// Bits of PoseMessage::foot_contact. Other bits are sent as 0 and ignored on receipt.
enum FootContact : std::uint8_t {
  kFootContactLeft = 1u << 0,   // Toes_L is in contact with the floor
  kFootContactRight = 1u << 1,  // Toes_R is in contact with the floor
};

// The global pose of one joint: T_world_joint, metres, unit quaternion in (x, y, z, w).
struct JointState {
  std::array<float, 3> position_m{};
  std::array<float, 4> rotation_xyzw{0.0f, 0.0f, 0.0f, 1.0f};
};

// Marks "no root joint" in PoseMessage::root_joint.
inline constexpr std::uint16_t kNoRootJoint = 0xFFFF;

// One reconstructed full-body pose (topic "pose").
struct PoseMessage {
  std::uint64_t seq = 0;           // +1 per published pose; a gap means poses were dropped
  std::int64_t t_ns = 0;           // time the pose is for: newest tracker sample used (publisher's CLOCK_MONOTONIC)
  std::int64_t publish_t_ns = 0;   // time the message was published (publisher's CLOCK_MONOTONIC)
  std::uint32_t flags = 0;         // PoseFlags
  std::uint32_t skeleton_id = 0;   // SkeletonMessage::skeleton_id of the skeleton the joints follow
  std::uint16_t root_joint = kNoRootJoint;  // index of the root (Hips) joint in `joints`
  std::uint8_t foot_contact = 0;   // FootContact bits
  std::array<float, 3> root_position_m{};  // Hips global position (world, metres)
  float root_heading_rad = 0.0f;   // Hips yaw about +Y: atan2(f.x, f.z) of the Hips' +Z axis f, in (-pi, pi]
  std::vector<JointState> joints;  // global pose per skeleton joint, in skeleton order
};

// ---- Skeleton message ----------------------------------------------------------------

// The skeleton that PoseMessage::joints follow (topic "skeleton", and the control reply).
struct SkeletonMessage {
  std::uint32_t skeleton_id = 0;  // skeleton_id_of(*this); never 0 on the wire
  std::vector<std::string> names;   // UTF-8, 1..kMaxJointNameBytes bytes, unique
  std::vector<std::int16_t> parents;  // -1 for the root; otherwise < own index
  std::vector<std::array<float, 3>> offsets_m;  // rest offset from the parent, in the parent's frame, metres
  // Rest rotation of each joint relative to its parent (x, y, z, w), unit length: forward
  // kinematics of offsets_m and these gives the skeleton's reference T-pose (docs/protocol.md,
  // "Rest pose"). Empty when unknown: such a skeleton is encoded as a version-1 message, and a
  // version-1 message decodes with it empty.
  std::vector<std::array<float, 4>> rest_rotations_xyzw;
};

// ---- Results ---------------------------------------------------------------------------

// Success, or what is wrong. Allocation-free on success.
struct [[nodiscard]] Status {
  std::string error;  // empty on success; otherwise names the field and what is wrong
  [[nodiscard]] bool ok() const { return error.empty(); }
  explicit operator bool() const { return ok(); }
};

// ---- Encoding (struct in, bytes out) ---------------------------------------------------

// Encodes `pose` into `out` (resized; no allocation when `out` already has the capacity).
// Fails only if the pose cannot be represented: more than kMaxJoints joints, a root_joint
// out of range, or non-finite numbers.
Status encode_pose(const PoseMessage& pose, std::vector<std::uint8_t>& out);

// Encodes `skeleton` into `out`: version 2 with rest rotations, version 1 when it has none.
// The skeleton_id written is skeleton_id_of(skeleton), whatever skeleton.skeleton_id holds.
// Fails if the skeleton is invalid (see validate_skeleton).
Status encode_skeleton(const SkeletonMessage& skeleton, std::vector<std::uint8_t>& out);

// The identifier of a skeleton: FNV-1a (32 bit) over its joint table as encoded on the
// wire (see docs/protocol.md), with 0 replaced by 1. Changes whenever a name, a parent or an
// offset changes (a new user height gives new offsets, hence a new id).
[[nodiscard]] std::uint32_t skeleton_id_of(const SkeletonMessage& skeleton);

// Checks the invariants of SkeletonMessage (not the id); returns what is wrong, if anything.
Status validate_skeleton(const SkeletonMessage& skeleton);

// ---- Decoding (bytes in, struct out) ---------------------------------------------------

// Decodes a pose message frame. On failure `out` is unspecified, nothing is read outside
// `bytes`, and the status names what is wrong. Reuses `out.joints`' capacity.
Status decode_pose(std::span<const std::uint8_t> bytes, PoseMessage& out);

// Decodes a skeleton message frame (version 1 or 2), checking its id against the hash of its
// joint table.
Status decode_skeleton(std::span<const std::uint8_t> bytes, SkeletonMessage& out);

// ---- Helpers ---------------------------------------------------------------------------

// Hips yaw as carried in PoseMessage::root_heading_rad, from a unit quaternion (x, y, z, w):
// the angle about +Y of the joint's +Z axis projected on the floor, atan2(f.x, f.z). 0 when
// that axis points straight up or down.
[[nodiscard]] float heading_rad_from_rotation(const std::array<float, 4>& rotation_xyzw);

// Convenience views of raw ZeroMQ frame data.
[[nodiscard]] inline std::span<const std::uint8_t> as_bytes(const void* data, std::size_t size) {
  return {static_cast<const std::uint8_t*>(data), size};
}

}  // namespace bodyd::protocol
