// Pure decoders of the network inputs (docs/vr-apps.md, docs/drivers.md "Network inputs"):
// bytes in, values or a reason out, no I/O, no clock, so that they can be fuzzed
// (tests/drivers/fuzz_targets.h) and tested with captured bytes.
//
//   OSC packet (message or bundle)  -> OscMessage list        decode_osc_packet (liblo decodes each message)
//   VRChat /tracking/vrsystem/*/pose -> VrchatPose           decode_vrchat_message
//   VMC /VMC/Ext/{Hmd,Con,Tra}/Pos   -> VmcPose              decode_vmc_message
//   one tracker-log v1 line          -> TrackerSample        decode_tracker_line (motion/'s tracker-log parser)
//   Unity's axes -> bodyd's axes                             unity_*_to_bodyd
//
// A decoder either accepts (the values are finite and plausible, rotations unit length
// after conversion), ignores (well-formed traffic this input does not use: another OSC
// address), or rejects with one InputReject reason. Nothing a sender can put in a packet
// makes a decoder crash or yield a non-finite value.
#pragma once

#include "bodyd/motion/limits.h"
#include "bodyd/motion/tracker.h"
#include "bodyd/motion/unity_axes.h"
#include "bodyd/io/vrchat/unity_euler.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::drivers {

// Why a packet or message was rejected; each reason has its own counter in `status`.
enum class InputReject : std::uint8_t {
  None = 0,
  Truncated,      // shorter than its own structure says (message, string, argument, bundle element)
  NotOsc,         // neither a message (address starting with '/') nor a "#bundle"
  BadTypeTags,    // an address this input knows, with the wrong argument types
  WrongArgCount,  // an address this input knows, with too few or too many arguments
  NonFinite,      // NaN or infinity in a position or rotation
  AbsurdValue,    // finite but implausible (beyond the limits below, quaternion far from unit length)
  Oversized,      // datagram, bundle nesting or message count beyond the limits below
  BadLine,        // udp: the datagram is not one tracker-log v1 sample line
};
inline constexpr int kInputRejectCount = 9;
// "truncated", "not_osc", "bad_type_tags", "wrong_arg_count", "non_finite", "absurd_value",
// "oversized", "bad_line" (the keys of status' "rejected_by_reason"); "none" for None.
[[nodiscard]] std::string_view input_reject_name(InputReject reason);

// Plausibility: positions within limits::kMaxAbsPositionM per coordinate and quaternions
// within limits::kQuatNormTolerance of unit length (bodyd/motion/limits.h, shared by every
// input); Euler angles within kMaxAbsEulerDeg (Unity writes them in [0, 360)).
inline constexpr double kMaxAbsEulerDeg = 3600.0;

struct OscLimits {
  std::size_t max_packet_bytes = 32768;  // a larger datagram is rejected (Oversized) undecoded
  std::size_t max_messages = 512;        // per packet, over all nested bundles
  int max_bundle_depth = 4;              // a bundle inside a bundle inside ... at most this deep
};

// One OSC argument. Numbers (f, d, i, h) are kept as double (f and i convert exactly);
// strings (s, S) in `text`; other types keep only their tag.
struct OscArg {
  char type = 0;
  double number = 0.0;
  std::string text;
};

struct OscMessage {
  std::string address;
  std::string type_tags;  // without the leading ','
  std::vector<OscArg> args;
};

// Decodes a datagram: a message, or a bundle (elements walked here: "#bundle\0", an
// 8-byte time tag, then int32 big-endian size + element, each element a message or a
// bundle; OSC 1.0 spec) whose messages liblo decodes (lo_message_deserialise). Time tags
// are ignored: every message of a datagram is stamped with its arrival. On a reject,
// `out` is empty and `out_detail` says what and where (for the log).
[[nodiscard]] InputReject decode_osc_packet(const std::uint8_t* data, std::size_t size, std::vector<OscMessage>& out,
                                            std::string& out_detail, const OscLimits& limits = {});

enum class MessageUse : std::uint8_t { Use, Ignore, Reject };

// ---- VRChat: /tracking/vrsystem/{head,leftwrist,rightwrist}/pose, six floats ----------------
// Position x, y, z in metres and rotation as Euler angles x, y, z in degrees, in Unity's
// left-handed axes (x right, y up, z forward); the angles are Unity's: the rotation turns z
// degrees about z, then x about x, then y about y (Quaternion.Euler; SlimeVR decodes them the
// same way, EulerOrder.YXZ).
struct VrchatPose {
  Role role = Role::Head;  // head, leftwrist -> LeftHand, rightwrist -> RightHand
  std::array<double, 3> position_unity{};
  std::array<double, 3> euler_deg_unity{};
};
[[nodiscard]] MessageUse decode_vrchat_message(const OscMessage& message, VrchatPose& out, InputReject& out_reject);
// The sample bodyd's reconstruction sees (axes converted; the wrist -> Hand_* offset is the
// daemon's per-role device offset, docs/vr-apps.md).
[[nodiscard]] TrackerSample sample_from_vrchat(const VrchatPose& pose, std::int64_t t_ns);

// ---- VMC: /VMC/Ext/{Hmd,Con,Tra}/Pos serial px py pz qx qy qz qw (Unity axes) -------------------
enum class VmcDevice : std::uint8_t { Hmd, Controller, Tracker };
struct VmcPose {
  VmcDevice device = VmcDevice::Hmd;
  std::string serial;
  Vec3 position_m = Vec3::Zero();      // converted to bodyd's axes
  Quat rotation = Quat::Identity();    // converted to bodyd's axes, unit length
};
[[nodiscard]] MessageUse decode_vmc_message(const OscMessage& message, VmcPose& out, InputReject& out_reject);

// ---- udp: one tracker-log v1 sample line per datagram -------------------------------------------
// The line as docs/tracker-log.md writes it (a trailing "\n" or "\r\n" is allowed). The
// header line and '#' lines are ignored, so a whole log can be streamed line by line. The
// line's t_ns is the sender's clock (`out_sender_t_ns`); the source stamps t_ns on arrival.
[[nodiscard]] MessageUse decode_tracker_line(const std::uint8_t* data, std::size_t size, TrackerSample& out_sample,
                                             std::int64_t& out_sender_t_ns, InputReject& out_reject,
                                             std::string& out_detail);
inline constexpr std::size_t kMaxTrackerLineBytes = 1024;

// ---- Unity <-> bodyd axes --------------------------------------------------------------------------
// The mirror S = diag(1, 1, -1) of bodyd/motion/unity_axes.h (its own inverse, so these convert back too).
[[nodiscard]] inline Vec3 unity_position_to_bodyd(const Vec3& p_unity) { return bodyd_from_unity(p_unity); }
[[nodiscard]] inline Quat unity_rotation_to_bodyd(const Quat& q_unity) { return bodyd_from_unity(q_unity); }
// Unity's Quaternion.Euler(x, y, z): unity_euler_deg_to_quat, with its inverse in
// bodyd/io/vrchat/unity_euler.h.

}  // namespace bodyd::drivers
