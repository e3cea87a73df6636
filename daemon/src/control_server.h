// The control socket (docs/control.md): a ROUTER socket answering REQ clients, each request
// with its own envelope, and the thread that answers it. The
// requests are parsed by control.h's handle_control_request, which calls the ControlTarget.
#pragma once

#include "bodyd/daemon/control.h"
#include "zmq_util.h"

#include <atomic>
#include <string>
#include <thread>

namespace bodyd::daemon {

struct DaemonConfig;

class ControlServer {
 public:
  ~ControlServer() { stop(); }
  // Binds config.control_endpoint ("" or "none": nothing to do; enabled() stays false).
  [[nodiscard]] std::string open(const DaemonConfig& config);
  // Starts the thread answering requests with `target` (which must outlive stop()).
  void start(ControlTarget& target);
  // Joins the thread and closes the socket (idempotent).
  void stop();

  [[nodiscard]] bool enabled() const { return socket_.get() != nullptr; }
  [[nodiscard]] const std::string& bound() const { return bound_; }

 private:
  void loop(ControlTarget& target);

  ZmqSocket socket_;
  std::string bound_, curve_public_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace bodyd::daemon
