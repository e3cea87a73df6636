// The steamvr: source: a BridgeSource (bridge_source.h) on SlimeVR's OpenVR driver socket.
#include "bridge_source.h"

#include "bodyd/io/open_source.h"

#include <string>
#include <string_view>

namespace bodyd::drivers::slimevr {

std::unique_ptr<TrackerSource> open_steamvr_source(std::string_view spec, std::string_view argument, std::string& error) {
  std::string e;
  const std::string path = socket_path(argument, kDriverSocketName, e, default_driver_socket_dir);
  if (path.empty()) {
    error = "--source " + std::string(spec) + ": " + e;
    return nullptr;
  }
  warn_if_shadowed(path);
  return std::make_unique<BridgeSource>("steamvr:" + path, shared_bridge(path));
}

}  // namespace bodyd::drivers::slimevr

namespace bodyd::drivers {

// The registry's factory (sources.cpp): steamvr[:SOCKET].
std::unique_ptr<TrackerSource> open_steamvr_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  return slimevr::open_steamvr_source(spec.text, spec.argument, error);
}

}  // namespace bodyd::drivers
