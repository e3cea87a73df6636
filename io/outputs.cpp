// The registered outputs: one row per output kind (io/include/bodyd/io/output.h says
// how to add one). Each factory lives in its output's own file.
#include "bodyd/io/output.h"
#include "bodyd/io/vmc/vmc.h"
#include "bodyd/io/zmq/zmq_publisher.h"

namespace bodyd::daemon {

// The factories (each in its output_NAME.cpp; see output.h).
std::unique_ptr<Output> make_vrchat_output(const OutputSpec& spec, const OutputEnv& env, std::string& error);
std::unique_ptr<Output> make_steamvr_output(const OutputSpec& spec, const OutputEnv& env, std::string& error);
std::unique_ptr<Output> make_monado_output(const OutputSpec& spec, const OutputEnv& env, std::string& error);

const std::vector<OutputKind>& output_kinds() {
  static const std::vector<OutputKind> kinds = {
      {"zmq", make_zmq_output, "zmq:ENDPOINT  another ZeroMQ pose stream (docs/protocol.md), like --pub"},
      {"vmc", make_vmc_output, "vmc:[HOST:PORT]  VMC protocol to a marionette: VSeeFace, VNyan, Warudo, EVMC4U (default 127.0.0.1:39539)"},
      {"vrchat", make_vrchat_output, "vrchat:[HOST:PORT][?slots=hip,feet,...]  VRChat OSC trackers (default 127.0.0.1:9000)"},
      {"steamvr", make_steamvr_output, "steamvr[:SOCKET][?trackers=waist,feet,...]  SteamVR trackers through SlimeVR's OpenVR driver (default $XDG_RUNTIME_DIR/SlimeVRDriver)"},
      {"monado", make_monado_output, "monado[:DIR][?trackers=waist,feet,...]  Monado/WiVRn body tracking over SolarXR on DIR/SlimeVRRpc (default $XDG_RUNTIME_DIR)"},
  };
  return kinds;
}

}  // namespace bodyd::daemon
