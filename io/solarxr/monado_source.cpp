// The monado: source: a BridgeSource (../slimevr/bridge_source.h) on the socket Monado's and
// WiVRn's SlimeVR driver connects to (DIR/SlimeVRInput).
#include "slimevr/bridge_source.h"

#include "bodyd/io/open_source.h"

#include <string>
#include <string_view>

namespace bodyd::drivers::slimevr {

std::unique_ptr<TrackerSource> open_monado_source(std::string_view spec, std::string_view argument, std::string& error) {
  std::string e;
  std::string dir(argument);
  if (dir.empty()) dir = default_socket_dir(e);
  std::string path = dir.empty() ? std::string() : socket_path(dir + "/" + std::string(kMonadoInputSocketName), {}, e);
  if (path.empty()) {
    error = "--source " + std::string(spec) + ": " + e;
    return nullptr;
  }
  return std::make_unique<BridgeSource>("monado:" + path, shared_bridge(path));
}

}  // namespace bodyd::drivers::slimevr

namespace bodyd::drivers {

// The registry's factory (sources.cpp): monado[:DIR].
std::unique_ptr<TrackerSource> open_monado_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  return slimevr::open_monado_source(spec.text, spec.argument, error);
}

}  // namespace bodyd::drivers
