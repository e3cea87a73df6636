#include "bodyd/drivers/open_source.h"

#include "bodyd/drivers/device_list.h"
#include "bodyd/drivers/sim_source.h"

namespace bodyd::drivers {

std::optional<SourceSpec> parse_source_spec(std::string_view text, std::string& error) {
  struct Prefix {
    std::string_view text;
    SourceKind kind;
  };
  static constexpr Prefix kPrefixes[] = {{"replay:", SourceKind::Replay},
                                         {"sim:", SourceKind::Sim},
                                         {"hid:", SourceKind::Hid},
                                         {"usb:", SourceKind::Usb}};
  for (const Prefix& p : kPrefixes) {
    if (text.substr(0, p.text.size()) != p.text) continue;
    SourceSpec spec{p.kind, std::string(text.substr(p.text.size()))};
    if (spec.argument.empty()) {
      error = "source \"" + std::string(text) + "\": missing " +
              (p.kind == SourceKind::Replay || p.kind == SourceKind::Sim ? "file" : "VID:PID") + " after '" +
              std::string(p.text) + "'";
      return std::nullopt;
    }
    return spec;
  }
  error = "source \"" + std::string(text) +
          "\": unknown kind; expected replay:FILE, sim:FILE.bvh, hid:VID:PID or usb:VID:PID";
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
  }
  error = "source \"" + std::string(text) + "\": unknown kind";
  return nullptr;
}

}  // namespace bodyd::drivers
