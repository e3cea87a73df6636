// The control socket (docs/control.md): a ROUTER socket answering REQ clients, each request
// with its own envelope, and the thread that answers it. The requests are parsed by control.h's
// answer_control_request, which calls the ControlTarget. A request whose answer comes later (the
// calibration pose's wait) keeps its envelope here and is answered when its LaterReply gives the
// reply, while the thread goes on answering everyone else.
#pragma once

#include "bodyd/daemon/control.h"
#include "bodyd/io/zmq/zmq_util.h"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <thread>
#include <vector>

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
  // Connection accounting from the socket monitor (docs/reliability.md, "Control socket").
  void on_monitor_event(std::uint16_t event, std::uint32_t value);
  void evict_idlest();
  void drop_listener();
  void retry_listener();
  // Sends `text` to the peer of `envelope` (its routing id .. empty delimiter); false when the
  // peer has gone or does not read.
  bool send_reply(const std::vector<std::string>& envelope, const std::string& text);
  // Answers the waiting requests whose replies are ready (all of them with `stopping`).
  void answer_waiting(bool stopping);

  using Clock = std::chrono::steady_clock;
  struct Peer {
    Clock::time_point last_active;  // accepted, or last request
    std::uint64_t order = 0;        // accept order, for ties
  };

  struct Waiting {
    std::vector<std::string> envelope;
    LaterReply later;
  };
  std::vector<Waiting> waiting_;  // requests answered later, oldest first (control thread)

  ZmqSocket socket_;
  void* monitor_ = nullptr;  // PAIR receiving the ROUTER's monitor events (control thread)
  std::map<int, Peer> peers_;  // by descriptor: the connections open now
  std::uint64_t next_order_ = 0;
  int evicting_fd_ = -1;       // shut down, its DISCONNECTED event not seen yet
  std::size_t max_peers_ = 64;
  bool listener_dropped_ = false;
  Clock::time_point rebind_at_{};
  std::chrono::milliseconds backoff_{100};
  bool cap_logged_ = false, exhaustion_logged_ = false;
  std::string bound_, curve_public_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace bodyd::daemon
