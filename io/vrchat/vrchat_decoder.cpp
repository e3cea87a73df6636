// vrchat: VRChat's OSC tracking output (/tracking/vrsystem/{head,leftwrist,rightwrist}/pose),
// with an OSCQuery service announced over mDNS so that VRChat finds bodyd (network_source.h,
// docs/vr-apps.md).
#include "osc/network_protocol.h"
#include "oscquery.h"

#include <spdlog/spdlog.h>

namespace bodyd::drivers::detail {
namespace {

class VrchatDecoder final : public OscDecoder {
 public:
  explicit VrchatDecoder(const NetworkSourceOptions& o) : OscDecoder(o.limits) {}

  std::string open(const NetworkSourceOptions& o, int bound_port) override {
    if (!o.oscquery) return {};
    std::string error;
    oscquery_ = OscQueryService::start(o.oscquery_name, o.host, bound_port, error);
    if (!oscquery_) return o.name + ": " + error;
    spdlog::info("{}: OSCQuery on http://{}:{}/ (VRChat finds bodyd through it when mDNS works)", o.name,
                 o.host == "0.0.0.0" ? "127.0.0.1" : o.host, oscquery_->http_port());
    return {};
  }
  int oscquery_port() const override { return oscquery_ ? oscquery_->http_port() : 0; }
  std::string mdns_state() const override { return oscquery_ ? oscquery_->mdns_state() : "off"; }

 protected:
  MessageUse message(const OscMessage& m, std::int64_t arrival_ns, DatagramResult& out, InputReject& why) override {
    VrchatPose pose;
    const MessageUse use = decode_vrchat_message(m, pose, why);
    if (use == MessageUse::Use) out.use(sample_from_vrchat(pose, arrival_ns));
    return use;
  }

 private:
  std::unique_ptr<OscQueryService> oscquery_;
};

}  // namespace

std::unique_ptr<NetworkDecoder> make_vrchat_decoder(const NetworkSourceOptions& o) {
  return std::make_unique<VrchatDecoder>(o);
}

bool vrchat_option(const std::string& key, const std::string& value, NetworkSourceOptions& o) {
  if (key == "oscquery" && (value == "on" || value == "off")) {
    o.oscquery = value == "on";
    return true;
  }
  if (key == "name" && !value.empty()) {
    o.oscquery_name = value;
    return true;
  }
  return false;
}

}  // namespace bodyd::drivers::detail
