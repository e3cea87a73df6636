// Network inputs: tracker sources that listen on a UDP port (docs/vr-apps.md, docs/drivers.md
// "Network inputs").
//
//   vrchat:[HOST:]PORT  VRChat's /tracking/vrsystem/{head,leftwrist,rightwrist}/pose (OSC), with an
//                       OSCQuery HTTP endpoint announced over mDNS so that VRChat finds bodyd.
//                       Default 127.0.0.1:9001 (VRChat's default OSC output port).
//   vmc:[HOST:]PORT     VMC protocol /VMC/Ext/{Hmd,Con,Tra}/Pos (VirtualMotionCapture, SlimeVR).
//                       Default 127.0.0.1:39539. Options: ?head=SERIAL&left_hand=SERIAL&right_hand=SERIAL.
//   udp:[HOST:]PORT     one tracker-log v1 line per datagram (docs/tracker-log.md).
//
// One thread per source reads the socket with a 100 ms timeout (so stop() is prompt),
// stamps each datagram with monotonic_ns() as soon as recvfrom returns, hands it to the
// protocol's decoder (one per protocol, io/osc/network_protocol.h, built on the pure
// decoders of osc_decode.h), and pushes the samples (t_ns = the arrival stamp). A
// malformed packet is counted by reason (status().counters, "rejected_by_reason"), logged at
// a limited rate (the 1st, 2nd, 4th, 8th... of each source) and dropped; it never reaches
// the reconstruction.
//
// Security: OSC has no authentication; anyone who can reach the port can move the avatar.
// A source binds to loopback unless `allow_remote` (the daemon's --allow-remote) is set.
#pragma once

#include "bodyd/io/osc/osc_decode.h"
#include "bodyd/io/source.h"

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

namespace bodyd::drivers {

// Which UDP protocol a network input speaks, by its scheme: a row of the protocol table
// (io/osc/network_protocols.cpp; a protocol's decoder is a file of its own, docs/architecture.md
// "A new tracker source"). `scheme` must outlive the options (a literal, or a registry row's).
struct NetworkKind {
  std::string_view scheme;  // "vrchat", "vmc", "udp"
  friend bool operator==(const NetworkKind&, const NetworkKind&) = default;
  // The built-in protocols, for code that names one (a new protocol needs no constant here).
  static const NetworkKind Vrchat, Vmc, Udp;
};
inline constexpr NetworkKind NetworkKind::Vrchat{"vrchat"};
inline constexpr NetworkKind NetworkKind::Vmc{"vmc"};
inline constexpr NetworkKind NetworkKind::Udp{"udp"};

struct NetworkSourceOptions {
  NetworkKind kind = NetworkKind::Vrchat;
  std::string name;              // status name: the spec it came from
  std::string host = "127.0.0.1";
  int port = 0;                  // 0: any free port (tests; bound_port() says which)
  bool allow_remote = false;     // bind to a non-loopback address
  // vrchat:
  bool oscquery = true;          // serve OSCQuery (HTTP) and announce it over mDNS
  std::string oscquery_name = "bodyd";
  // vmc: serial -> role; roles not named here are assigned automatically (docs/vr-apps.md).
  std::map<std::string, Role> vmc_roles;
  OscLimits limits;
};

// Parses the argument of "vrchat:", "vmc:" or "udp:" ("[HOST:]PORT[?key=value&...]").
// Defaults: host 127.0.0.1; the protocol's default port, 9001 (vrchat), 39539 (vmc); udp needs a port.
[[nodiscard]] std::optional<NetworkSourceOptions> parse_network_spec(NetworkKind kind, std::string_view spec,
                                                                     std::string_view argument, std::string& error);

struct NetworkStats {
  std::uint64_t datagrams = 0;   // received
  std::uint64_t samples = 0;     // pushed to the sink
  std::uint64_t ignored = 0;     // well-formed messages this input does not use (other OSC addresses)
  std::uint64_t unassigned = 0;  // vmc: poses of a serial with no role (yet)
  std::array<std::uint64_t, kInputRejectCount> rejected{};  // by InputReject
  [[nodiscard]] std::uint64_t rejected_total() const;
};

class NetworkSource : public TrackerSource {
 public:
  [[nodiscard]] virtual int bound_port() const = 0;
  [[nodiscard]] virtual NetworkStats stats() const = 0;
  // vrchat: the OSCQuery HTTP port (0 when off or not started), and what mDNS is doing
  // ("announced", "avahi-daemon is not running ...", "off").
  [[nodiscard]] virtual int oscquery_port() const { return 0; }
  [[nodiscard]] virtual std::string mdns_state() const { return "off"; }
};

// Binds the socket (so a busy port or a refused address is reported at once). nullptr and
// `error` ("vmc:0.0.0.0:39539: ...: what to do") on failure.
[[nodiscard]] std::unique_ptr<NetworkSource> open_network_source(const NetworkSourceOptions& options,
                                                                 std::string& error);

}  // namespace bodyd::drivers
