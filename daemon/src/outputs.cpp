// The registered outputs: one row per output kind (daemon/include/bodyd/daemon/output.h says
// how to add one). Each factory lives in its output's own file.
#include "bodyd/daemon/output.h"
#include "zmq_publisher.h"

namespace bodyd::daemon {

const std::vector<OutputKind>& output_kinds() {
  static const std::vector<OutputKind> kinds = {
      {"zmq", make_zmq_output, "zmq:ENDPOINT  another ZeroMQ pose stream (docs/protocol.md), like --pub"},
  };
  return kinds;
}

}  // namespace bodyd::daemon
