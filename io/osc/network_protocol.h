// The UDP protocols of the network inputs (network_source.h): one row per protocol
// (network_protocols.cpp) and one decoder per protocol, each in its own file
// (vrchat_decoder.cpp, vmc_decoder.cpp, udp_line_decoder.cpp). UdpSource owns the socket,
// the receiver thread, the counters and the rate-limited log; a decoder turns one datagram
// into samples and says what it ignored or rejected.
#pragma once

#include "bodyd/io/osc/network_source.h"
#include "bodyd/io/osc/osc_decode.h"

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::drivers::detail {

// What a decoder found in one datagram; called on the receiver thread.
class DatagramResult {
 public:
  virtual ~DatagramResult() = default;
  // A sample to push (t_ns is the arrival stamp), with the sender's clock when it has one.
  virtual void use(const TrackerSample& sample, std::int64_t device_t_ns = 0, bool has_device_time = false) = 0;
  virtual void ignore() = 0;      // a well-formed message this input does not use
  virtual void unassigned() = 0;  // a pose of a device that has no role (yet)
  virtual void reject(InputReject why, const std::string& detail) = 0;  // counted, logged, dropped
};

// One protocol's decoding, made per source (it may keep state, e.g. vmc:'s role assignment).
class NetworkDecoder {
 public:
  virtual ~NetworkDecoder() = default;
  // Called once the socket is bound to `bound_port` (vrchat: starts OSCQuery). Empty, or what went wrong.
  [[nodiscard]] virtual std::string open(const NetworkSourceOptions& /*options*/, int /*bound_port*/) { return {}; }
  // One datagram of `size` bytes that arrived at `arrival_ns`.
  virtual void decode(const std::uint8_t* data, std::size_t size, std::int64_t arrival_ns, DatagramResult& out) = 0;
  // Counters of its own in the source's status (vmc: "unassigned").
  virtual void add_counters(const NetworkStats& /*stats*/, SourceStatus& /*status*/) const {}
  [[nodiscard]] virtual int oscquery_port() const { return 0; }
  [[nodiscard]] virtual std::string mdns_state() const { return "off"; }
};

// The OSC protocols' common part: a packet (message or bundle) decoded into messages, then
// each message handled by the protocol.
class OscDecoder : public NetworkDecoder {
 public:
  explicit OscDecoder(const OscLimits& limits) : limits_(limits) {}
  void decode(const std::uint8_t* data, std::size_t size, std::int64_t arrival_ns, DatagramResult& out) final;

 protected:
  // One message: Use (and out.use), Ignore, or Reject with `why`.
  virtual MessageUse message(const OscMessage& m, std::int64_t arrival_ns, DatagramResult& out, InputReject& why) = 0;

 private:
  OscLimits limits_;
  std::vector<OscMessage> messages_;
};

// One row of the protocol table.
struct NetworkProtocol {
  std::string_view scheme;        // "vrchat": the source scheme (a row of sources.cpp) and NetworkKind
  int default_port = 0;           // 0: the spec must give the port
  std::string_view options_help;  // "vrchat: takes oscquery=on|off and name=NAME" (unknown-option error)
  // Takes one "key=value" of the spec's options into `o`; false: not an option of this protocol.
  bool (*option)(const std::string& key, const std::string& value, NetworkSourceOptions& o) = nullptr;
  std::unique_ptr<NetworkDecoder> (*decoder)(const NetworkSourceOptions& o) = nullptr;
};

[[nodiscard]] const std::vector<NetworkProtocol>& network_protocols();
// The row of `kind`, or nullptr.
[[nodiscard]] const NetworkProtocol* network_protocol(NetworkKind kind);

}  // namespace bodyd::drivers::detail
