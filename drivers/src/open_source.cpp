#include "bodyd/drivers/open_source.h"

#include "bodyd/drivers/device_list.h"
#include "bodyd/drivers/network_source.h"
#include "bodyd/drivers/sim_source.h"
#include "bodyd/drivers/slimevr_bridge.h"

namespace bodyd::drivers {

std::optional<SourceSpec> parse_source_spec(std::string_view text, std::string& error) {
  if (text == "steamvr" || text == "monado") return SourceSpec{text == "steamvr" ? SourceKind::Steamvr : SourceKind::Monado, ""};
  struct Prefix {
    std::string_view text;
    SourceKind kind;
  };
  static constexpr Prefix kPrefixes[] = {{"replay:", SourceKind::Replay},
                                         {"sim:", SourceKind::Sim},
                                         {"hid:", SourceKind::Hid},
                                         {"usb:", SourceKind::Usb},
                                         {"vrchat:", SourceKind::Vrchat},
                                         {"vmc:", SourceKind::Vmc},
                                         {"udp:", SourceKind::Udp},
                                         {"steamvr:", SourceKind::Steamvr},
                                         {"monado:", SourceKind::Monado}};
  for (const Prefix& p : kPrefixes) {
    if (text.substr(0, p.text.size()) != p.text) continue;
    SourceSpec spec{p.kind, std::string(text.substr(p.text.size()))};
    // vrchat: and vmc: have a default address; udp: says itself what it misses.
    const bool network = p.kind == SourceKind::Vrchat || p.kind == SourceKind::Vmc || p.kind == SourceKind::Udp ||
                         p.kind == SourceKind::Steamvr || p.kind == SourceKind::Monado;
    if (spec.argument.empty() && !network) {
      error = "source \"" + std::string(text) + "\": missing " +
              (p.kind == SourceKind::Replay || p.kind == SourceKind::Sim ? "file" : "VID:PID") + " after '" +
              std::string(p.text) + "'";
      return std::nullopt;
    }
    return spec;
  }
  error = "source \"" + std::string(text) +
          "\": unknown kind; expected replay:FILE, sim:FILE.bvh, hid:VID:PID, usb:VID:PID, vrchat:[HOST:]PORT, "
          "vmc:[HOST:]PORT, udp:[HOST:]PORT, steamvr[:SOCKET] or monado[:DIR]";
  return std::nullopt;
}

std::unique_ptr<TrackerSource> open_source(std::string_view text, const SourceOptions& options,
                                           std::string& error) {
  const std::optional<SourceSpec> spec = parse_source_spec(text, error);
  if (!spec) return nullptr;
  switch (spec->kind) {
    case SourceKind::Replay: return open_replay_source(spec->argument, options.replay, error);
    case SourceKind::Sim: return open_sim_source(spec->argument, options.sim, options.replay, error);
    case SourceKind::Hid:
    case SourceKind::Usb: return open_device_source(text, spec->kind == SourceKind::Usb, spec->argument, error);
    case SourceKind::Vrchat:
    case SourceKind::Vmc:
    case SourceKind::Udp: {
      const NetworkKind kind = spec->kind == SourceKind::Vrchat ? NetworkKind::Vrchat
                               : spec->kind == SourceKind::Vmc  ? NetworkKind::Vmc
                                                                : NetworkKind::Udp;
      std::optional<NetworkSourceOptions> network = parse_network_spec(kind, text, spec->argument, error);
      if (!network) return nullptr;
      network->allow_remote = options.allow_remote;
      return open_network_source(*network, error);
    }
    case SourceKind::Steamvr: return slimevr::open_steamvr_source(text, spec->argument, error);
    case SourceKind::Monado: return slimevr::open_monado_source(text, spec->argument, error);
  }
  error = "source \"" + std::string(text) + "\": unknown kind";
  return nullptr;
}

}  // namespace bodyd::drivers
