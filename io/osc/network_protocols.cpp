// The UDP protocols of the network inputs: one row per protocol (network_protocol.h). Each
// decoder and its options live in the protocol's own file.
#include "network_protocol.h"

#include "bodyd/motion/printable.h"

namespace bodyd::drivers::detail {

// The decoders and their options (each in its PROTOCOL_decoder.cpp).
std::unique_ptr<NetworkDecoder> make_vrchat_decoder(const NetworkSourceOptions& o);
bool vrchat_option(const std::string& key, const std::string& value, NetworkSourceOptions& o);
std::unique_ptr<NetworkDecoder> make_vmc_decoder(const NetworkSourceOptions& o);
bool vmc_option(const std::string& key, const std::string& value, NetworkSourceOptions& o);
std::unique_ptr<NetworkDecoder> make_udp_line_decoder(const NetworkSourceOptions& o);

namespace {
bool no_options(const std::string&, const std::string&, NetworkSourceOptions&) { return false; }
}  // namespace

const std::vector<NetworkProtocol>& network_protocols() {
  // scheme, default port, options help, options, decoder
  static const std::vector<NetworkProtocol> protocols = {
      {"vrchat", 9001, "vrchat: takes oscquery=on|off and name=NAME", vrchat_option, make_vrchat_decoder},
      {"vmc", 39539, "vmc: takes head=SERIAL, left_hand=SERIAL, right_hand=SERIAL", vmc_option, make_vmc_decoder},
      {"udp", 0, "udp: takes no options", no_options, make_udp_line_decoder},
  };
  return protocols;
}

const NetworkProtocol* network_protocol(NetworkKind kind) {
  for (const NetworkProtocol& p : network_protocols())
    if (p.scheme == kind.scheme) return &p;
  return nullptr;
}

void OscDecoder::decode(const std::uint8_t* data, std::size_t size, std::int64_t arrival_ns, DatagramResult& out) {
  std::string detail;
  if (InputReject why = decode_osc_packet(data, size, messages_, detail, limits_); why != InputReject::None) {
    out.reject(why, detail);
    return;
  }
  for (const OscMessage& m : messages_) {
    InputReject why = InputReject::None;
    const MessageUse use = message(m, arrival_ns, out, why);
    if (use == MessageUse::Ignore) out.ignore();
    if (use == MessageUse::Reject)
      out.reject(why, quote_printable(m.address, 64) + " with type tags ," + printable(m.type_tags));
  }
}

}  // namespace bodyd::drivers::detail
