// The monado: source: a BridgeSource (../slimevr/bridge_source.h) on the socket Monado's and
// WiVRn's SlimeVR driver connects to (DIR/SlimeVRInput).
#include "slimevr/bridge_source.h"

#include <string>

namespace bodyd::drivers {

// The registry's factory (sources.cpp): monado[:DIR], DIR by default default_socket_dir().
std::unique_ptr<TrackerSource> open_monado_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  std::string e;
  std::string dir = spec.argument;
  if (dir.empty()) dir = slimevr::default_socket_dir(e);
  const std::string path =
      dir.empty() ? std::string() : slimevr::socket_path(dir + "/" + std::string(slimevr::kMonadoInputSocketName), {}, e);
  return slimevr::open_bridge_source("monado", spec, path, e, error);
}

}  // namespace bodyd::drivers
