// The steamvr: source: a BridgeSource (bridge_source.h) on SlimeVR's OpenVR driver socket.
#include "bridge_source.h"

#include <string>
#include <string_view>

namespace bodyd::drivers::slimevr {

std::unique_ptr<TrackerSource> open_bridge_source(std::string_view scheme, const SourceSpec& spec,
                                                  const std::string& path, const std::string& path_error,
                                                  std::string& error) {
  if (path.empty()) {
    error = "--source " + spec.text + ": " + path_error;
    return nullptr;
  }
  return std::make_unique<BridgeSource>(std::string(scheme) + ":" + path, shared_bridge(path));
}

}  // namespace bodyd::drivers::slimevr

namespace bodyd::drivers {

// The registry's factory (sources.cpp): steamvr[:SOCKET], SOCKET by default
// default_driver_socket_dir()/SlimeVRDriver.
std::unique_ptr<TrackerSource> open_steamvr_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  std::string e;
  const std::string path = slimevr::socket_path(spec.argument, slimevr::kDriverSocketName, e,
                                                slimevr::default_driver_socket_dir);
  if (!path.empty()) slimevr::warn_if_shadowed(path);
  return slimevr::open_bridge_source("steamvr", spec, path, e, error);
}

}  // namespace bodyd::drivers
