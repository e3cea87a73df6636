#include "bodyd/io/osc/osc_decode.h"

#include "bodyd/motion/tracker_log.h"

#include <lo/lo.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>

namespace bodyd::drivers {

std::string_view input_reject_name(InputReject reason) {
  switch (reason) {
    case InputReject::None: return "none";
    case InputReject::Truncated: return "truncated";
    case InputReject::NotOsc: return "not_osc";
    case InputReject::BadTypeTags: return "bad_type_tags";
    case InputReject::WrongArgCount: return "wrong_arg_count";
    case InputReject::NonFinite: return "non_finite";
    case InputReject::AbsurdValue: return "absurd_value";
    case InputReject::Oversized: return "oversized";
    case InputReject::BadLine: return "bad_line";
  }
  return "unknown";
}

namespace {

constexpr std::uint8_t kBundleTag[8] = {'#', 'b', 'u', 'n', 'd', 'l', 'e', 0};

// An OSC address a decoder takes, and what it stands for.
template <class T>
struct KnownAddress {
  std::string_view address;
  T meaning;
};

// What `address` stands for in `table`; nullopt when the table lacks it.
template <class T, std::size_t N>
std::optional<T> meaning_of(const KnownAddress<T> (&table)[N], std::string_view address) {
  for (const KnownAddress<T>& known : table)
    if (known.address == address) return known.meaning;
  return std::nullopt;
}

std::uint32_t read_be32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]};
}

// liblo's deserialisation errors (lo_errors.h), as reject reasons.
InputReject reject_from_liblo(int code) {
  switch (code) {
    case LO_EINVALIDTYPE:
    case LO_EBADTYPE: return InputReject::BadTypeTags;
    case LO_EINVALIDPATH: return InputReject::NotOsc;
    default: return InputReject::Truncated;  // LO_ESIZE, LO_ETERM, LO_EPAD, LO_EINVALIDARG: the bytes end early or mid-field
  }
}

struct LoMessageFree {
  void operator()(lo_message m) const { lo_message_free(m); }
};

InputReject decode_message(const std::uint8_t* data, std::size_t size, OscMessage& out, std::string& detail) {
  if (size == 0 || data[0] != '/') {
    detail = "does not start with an OSC address ('/...') or \"#bundle\"";
    return InputReject::NotOsc;
  }
  int result = 0;
  // lo_message_deserialise copies what it keeps and does not write to `data`.
  std::unique_ptr<std::remove_pointer_t<lo_message>, LoMessageFree> m(
      lo_message_deserialise(const_cast<std::uint8_t*>(data), size, &result));
  if (!m) {
    detail = "liblo cannot decode the message (error " + std::to_string(result) + ")";
    return reject_from_liblo(result);
  }
  // The address is the NUL-terminated string the message starts with (liblo validated it).
  out.address.assign(reinterpret_cast<const char*>(data), strnlen(reinterpret_cast<const char*>(data), size));
  const char* types = lo_message_get_types(m.get());
  out.type_tags = types ? types : "";
  lo_arg** argv = lo_message_get_argv(m.get());
  const int argc = lo_message_get_argc(m.get());
  out.args.clear();
  out.args.reserve(static_cast<std::size_t>(argc));
  for (int i = 0; i < argc; ++i) {
    OscArg a;
    a.type = out.type_tags[static_cast<std::size_t>(i)];
    // By bytes: liblo packs the arguments at 4-byte steps, so an lo_arg (a union with 8-byte
    // members) may be misaligned and a member access on it is undefined behaviour.
    const auto read = [&]<typename T>(T value) {
      std::memcpy(&value, argv[i], sizeof value);
      return value;
    };
    switch (a.type) {
      case LO_FLOAT: a.number = read(0.0f); break;
      case LO_DOUBLE: a.number = read(0.0); break;
      case LO_INT32: a.number = read(std::int32_t{0}); break;
      case LO_INT64: a.number = static_cast<double>(read(std::int64_t{0})); break;
      case LO_STRING:
      case LO_SYMBOL: a.text = reinterpret_cast<const char*>(argv[i]); break;
      default: break;
    }
    out.args.push_back(std::move(a));
  }
  return InputReject::None;
}

InputReject decode_element(const std::uint8_t* data, std::size_t size, int depth, std::vector<OscMessage>& out,
                           std::string& detail, const OscLimits& limits) {
  if (size >= sizeof kBundleTag && std::memcmp(data, kBundleTag, sizeof kBundleTag) == 0) {
    if (depth >= limits.max_bundle_depth) {
      detail = "bundles nested more than " + std::to_string(limits.max_bundle_depth) + " deep";
      return InputReject::Oversized;
    }
    if (size < 16) {
      detail = "bundle of " + std::to_string(size) + " bytes ends inside its time tag";
      return InputReject::Truncated;
    }
    std::size_t at = 16;  // "#bundle\0" + 8-byte time tag (ignored: samples are stamped on arrival)
    while (at < size) {
      if (size - at < 4) {
        detail = "bundle element size at byte " + std::to_string(at) + " is cut off";
        return InputReject::Truncated;
      }
      const std::uint32_t n = read_be32(data + at);
      at += 4;
      if (n == 0 || n % 4 != 0) {
        detail = "bundle element at byte " + std::to_string(at - 4) + " has size " + std::to_string(n) +
                 " (must be a positive multiple of 4)";
        return InputReject::Truncated;
      }
      if (n > size - at) {
        detail = "bundle element at byte " + std::to_string(at - 4) + " claims " + std::to_string(n) + " bytes, " +
                 std::to_string(size - at) + " remain";
        return InputReject::Truncated;
      }
      if (InputReject r = decode_element(data + at, n, depth + 1, out, detail, limits); r != InputReject::None)
        return r;
      at += n;
    }
    return InputReject::None;
  }
  if (out.size() >= limits.max_messages) {
    detail = "more than " + std::to_string(limits.max_messages) + " messages in one packet";
    return InputReject::Oversized;
  }
  OscMessage m;
  if (InputReject r = decode_message(data, size, m, detail); r != InputReject::None) return r;
  out.push_back(std::move(m));
  return InputReject::None;
}

// Expected argument types: the count decides WrongArgCount, then each tag BadTypeTags.
InputReject check_types(const OscMessage& m, std::string_view expected) {
  if (m.type_tags.size() != expected.size()) return InputReject::WrongArgCount;
  return m.type_tags == expected ? InputReject::None : InputReject::BadTypeTags;
}

InputReject check_position(const Vec3& p) {
  if (!p.allFinite()) return InputReject::NonFinite;
  if (p.cwiseAbs().maxCoeff() > limits::kMaxAbsPositionM) return InputReject::AbsurdValue;
  return InputReject::None;
}

}  // namespace

InputReject decode_osc_packet(const std::uint8_t* data, std::size_t size, std::vector<OscMessage>& out,
                              std::string& out_detail, const OscLimits& limits) {
  out.clear();
  out_detail.clear();
  if (size > limits.max_packet_bytes) {
    out_detail = "datagram of " + std::to_string(size) + " bytes (limit " + std::to_string(limits.max_packet_bytes) + ")";
    return InputReject::Oversized;
  }
  if (size == 0) {
    out_detail = "empty datagram";
    return InputReject::Truncated;
  }
  const InputReject r = decode_element(data, size, 0, out, out_detail, limits);
  if (r != InputReject::None) out.clear();
  return r;
}

// ---------------------------------------------------------------------------------------------
MessageUse decode_vrchat_message(const OscMessage& m, VrchatPose& out, InputReject& out_reject) {
  out_reject = InputReject::None;
  static constexpr std::string_view kPrefix = "/tracking/vrsystem/";
  static constexpr KnownAddress<Role> kAddresses[] = {{"/tracking/vrsystem/head/pose", Role::Head},
                                                      {"/tracking/vrsystem/leftwrist/pose", Role::LeftHand},
                                                      {"/tracking/vrsystem/rightwrist/pose", Role::RightHand}};
  if (!m.address.starts_with(kPrefix)) return MessageUse::Ignore;
  const std::optional<Role> role = meaning_of(kAddresses, m.address);
  if (!role) return MessageUse::Ignore;
  if ((out_reject = check_types(m, "ffffff")) != InputReject::None) return MessageUse::Reject;
  out.role = *role;
  for (int i = 0; i < 3; ++i) {
    out.position_unity[i] = m.args[i].number;
    out.euler_deg_unity[i] = m.args[3 + i].number;
  }
  const Vec3 p(out.position_unity[0], out.position_unity[1], out.position_unity[2]);
  const Vec3 e(out.euler_deg_unity[0], out.euler_deg_unity[1], out.euler_deg_unity[2]);
  if ((out_reject = check_position(p)) != InputReject::None) return MessageUse::Reject;
  if (!e.allFinite()) out_reject = InputReject::NonFinite;
  else if (e.cwiseAbs().maxCoeff() > kMaxAbsEulerDeg) out_reject = InputReject::AbsurdValue;
  return out_reject == InputReject::None ? MessageUse::Use : MessageUse::Reject;
}

TrackerSample sample_from_vrchat(const VrchatPose& pose, std::int64_t t_ns) {
  TrackerSample s;
  s.t_ns = t_ns;
  s.role = pose.role;
  s.valid = true;
  s.position_m =
      unity_position_to_bodyd(Vec3(pose.position_unity[0], pose.position_unity[1], pose.position_unity[2]));
  s.rotation = unity_rotation_to_bodyd(
                   unity_euler_deg_to_quat(pose.euler_deg_unity[0], pose.euler_deg_unity[1], pose.euler_deg_unity[2]))
                   .normalized();
  return s;
}

// ---------------------------------------------------------------------------------------------
MessageUse decode_vmc_message(const OscMessage& m, VmcPose& out, InputReject& out_reject) {
  out_reject = InputReject::None;
  static constexpr KnownAddress<VmcDevice> kAddresses[] = {{"/VMC/Ext/Hmd/Pos", VmcDevice::Hmd},
                                                           {"/VMC/Ext/Con/Pos", VmcDevice::Controller},
                                                           {"/VMC/Ext/Tra/Pos", VmcDevice::Tracker}};
  const std::optional<VmcDevice> device = meaning_of(kAddresses, m.address);
  if (!device) return MessageUse::Ignore;  // bones, blend shapes, .../Pos/Local, ...
  if ((out_reject = check_types(m, "sfffffff")) != InputReject::None) return MessageUse::Reject;
  out.device = *device;
  out.serial = m.args[0].text;
  const Vec3 p(m.args[1].number, m.args[2].number, m.args[3].number);
  // Eigen's constructor takes (w, x, y, z); VMC writes x, y, z, w.
  const Quat q(m.args[7].number, m.args[4].number, m.args[5].number, m.args[6].number);
  if ((out_reject = check_position(p)) != InputReject::None) return MessageUse::Reject;
  if (!q.coeffs().allFinite()) out_reject = InputReject::NonFinite;
  else if (!(std::abs(q.norm() - 1.0) <= limits::kQuatNormTolerance)) out_reject = InputReject::AbsurdValue;
  if (out_reject != InputReject::None) return MessageUse::Reject;
  out.position_m = unity_position_to_bodyd(p);
  out.rotation = unity_rotation_to_bodyd(q).normalized();
  return MessageUse::Use;
}

// ---------------------------------------------------------------------------------------------
MessageUse decode_tracker_line(const std::uint8_t* data, std::size_t size, TrackerSample& out_sample,
                               std::int64_t& out_sender_t_ns, InputReject& out_reject, std::string& out_detail) {
  out_reject = InputReject::None;
  out_detail.clear();
  if (size > kMaxTrackerLineBytes) {
    out_reject = InputReject::Oversized;
    out_detail = "datagram of " + std::to_string(size) + " bytes (a tracker-log line is at most " +
                 std::to_string(kMaxTrackerLineBytes) + ")";
    return MessageUse::Reject;
  }
  std::string_view line(reinterpret_cast<const char*>(data), size);
  if (!line.empty() && line.back() == '\n') line.remove_suffix(1);
  if (line.find('\n') != std::string_view::npos || line.find('\0') != std::string_view::npos) {
    out_reject = InputReject::BadLine;
    out_detail = "more than one line (or a NUL byte) in one datagram: send one sample line per datagram";
    return MessageUse::Reject;
  }
  if (line.starts_with('#') || line.starts_with(kTrackerLogHeader)) return MessageUse::Ignore;
  // The tracker-log parser, primed with the version and header lines, decodes the line
  // exactly as a log file's line (a fresh parser each time: datagrams need not arrive in order).
  TrackerLogParser parser("datagram");
  try {
    (void)parser.feed_line(kTrackerLogVersionLine);
    (void)parser.feed_line(kTrackerLogHeader);
    const std::optional<TrackerSample> s = parser.feed_line(line);
    if (!s) return MessageUse::Ignore;  // blank
    out_sample = *s;
  } catch (const TrackerLogError& e) {
    out_reject = InputReject::BadLine;
    out_detail = e.what();
    return MessageUse::Reject;
  }
  out_sender_t_ns = out_sample.t_ns;
  if (out_sample.valid) {
    if ((out_reject = check_position(out_sample.position_m)) != InputReject::None) {
      out_detail = "position out of range";
      return MessageUse::Reject;
    }
    if (!out_sample.rotation.coeffs().allFinite()) {
      out_reject = InputReject::NonFinite;
      return MessageUse::Reject;
    }
  }
  return MessageUse::Use;
}

}  // namespace bodyd::drivers
