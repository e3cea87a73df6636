// vmc: the VMC protocol's /VMC/Ext/{Hmd,Con,Tra}/Pos poses, each serial given a role
// (vmc_roles.h; network_source.h, docs/vr-apps.md).
#include "osc/network_protocol.h"
#include "vmc_roles.h"

namespace bodyd::drivers::detail {
namespace {

class VmcDecoder final : public OscDecoder {
 public:
  explicit VmcDecoder(const NetworkSourceOptions& o) : OscDecoder(o.limits), roles_(o.name, o.vmc_roles) {}

  void add_counters(const NetworkStats& stats, SourceStatus& status) const override {
    status.counters["unassigned"] = stats.unassigned;
  }

 protected:
  MessageUse message(const OscMessage& m, std::int64_t arrival_ns, DatagramResult& out, InputReject& why) override {
    VmcPose pose;
    const MessageUse use = decode_vmc_message(m, pose, why);
    if (use != MessageUse::Use) return use;
    const std::optional<Role> role = roles_.role_of(pose, arrival_ns);
    if (!role) {
      out.unassigned();
      return MessageUse::Use;  // counted as unassigned, not as ignored
    }
    TrackerSample s;
    s.t_ns = arrival_ns;
    s.role = *role;
    s.valid = true;
    s.position_m = pose.position_m;
    s.rotation = pose.rotation;
    out.use(s);
    return MessageUse::Use;
  }

 private:
  VmcRoles roles_;
};

}  // namespace

std::unique_ptr<NetworkDecoder> make_vmc_decoder(const NetworkSourceOptions& o) { return std::make_unique<VmcDecoder>(o); }

bool vmc_option(const std::string& key, const std::string& value, NetworkSourceOptions& o) {
  const std::optional<Role> role = role_from_name(key);
  if (!role || value.empty()) return false;
  o.vmc_roles[value] = *role;
  return true;
}

}  // namespace bodyd::drivers::detail
