// udp: one tracker-log v1 line per datagram (docs/tracker-log.md; network_source.h).
#include "osc/network_protocol.h"

namespace bodyd::drivers::detail {
namespace {

class UdpLineDecoder final : public NetworkDecoder {
 public:
  void decode(const std::uint8_t* data, std::size_t size, std::int64_t arrival_ns, DatagramResult& out) override {
    TrackerSample s;
    std::int64_t sender_t_ns = 0;
    InputReject why = InputReject::None;
    std::string detail;
    switch (decode_tracker_line(data, size, s, sender_t_ns, why, detail)) {
      case MessageUse::Use:
        s.t_ns = arrival_ns;
        out.use(s, sender_t_ns, true);
        break;
      case MessageUse::Ignore: out.ignore(); break;
      case MessageUse::Reject: out.reject(why, detail); break;
    }
  }
};

}  // namespace

std::unique_ptr<NetworkDecoder> make_udp_line_decoder(const NetworkSourceOptions&) {
  return std::make_unique<UdpLineDecoder>();
}

}  // namespace bodyd::drivers::detail
