#include "control_server.h"

#include "bodyd/daemon/config.h"

#include <spdlog/spdlog.h>
#include <zmq.h>

#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/un.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string>
#include <vector>

namespace bodyd::daemon {

namespace {

// A request is a few bytes; refuse floods.
constexpr std::int64_t kMaxFrameBytes = 64 * 1024;
// A REQ client's envelope is its routing id and an empty delimiter; REQ/ROUTER chains add one
// frame per hop. A message with more frames than this is no request and is dropped unanswered.
constexpr std::size_t kMaxFrames = 32;

// Connections (issue 20 item 6). A peer that has not finished ZeroMQ's handshake within this is
// dropped by libzmq (a raw connection that sends nothing, or garbage).
constexpr int kHandshakeMs = 2000;
// At most this many connections, and at most a quarter of the descriptors still free when the
// socket is bound: beyond, the one idle the longest is closed, so a newcomer always gets in.
constexpr std::size_t kMaxPeers = 64;
constexpr std::size_t kMinPeers = 4;
constexpr const char* kMonitorEndpoint = "inproc://bodyd-control-monitor";

struct Frame {
  std::string data;
};

// Reads the rest of one message (every part is there once the first is: ZeroMQ delivers whole
// messages). Keeps at most kMaxFrames frames; returns false when there were more (the message
// is drained all the same). out_fd: the connection it came on (libzmq's SRCFD), or -1.
bool read_message(void* socket, zmq_msg_t& first, std::vector<Frame>& out, int& out_fd) {
  out.clear();
  out_fd = -1;
  bool within_limit = true;
  zmq_msg_t msg;
  zmq_msg_init(&msg);
  zmq_msg_move(&msg, &first);
  for (;;) {
    if (out.size() < kMaxFrames)
      out.push_back({std::string(static_cast<const char*>(zmq_msg_data(&msg)), zmq_msg_size(&msg))});
    else
      within_limit = false;
    if (const int fd = zmq_msg_get(&msg, ZMQ_SRCFD); fd >= 0) out_fd = fd;
    const bool more = zmq_msg_more(&msg);
    zmq_msg_close(&msg);
    if (!more) return within_limit;
    zmq_msg_init(&msg);
    if (zmq_msg_recv(&msg, socket, 0) < 0) {
      zmq_msg_close(&msg);
      return false;
    }
  }
}

}  // namespace

std::string ControlServer::open(const DaemonConfig& config) {
  if (config.control_endpoint.empty() || config.control_endpoint == "none") return {};
  // A ROUTER socket, not REP: REP's one state machine for all peers could be left mid-envelope
  // by one peer's malformed message (libzmq 4.3: a message with no delimiter from a peer that has
  // already gone leaves the reply path half open, and the next peer's reply is lost), and it
  // holds one request at a time. Here every request carries its peer's envelope, is answered on
  // its own, and a malformed one is dropped without touching any other peer (issue 11 item 7).
  // On the wire it is the same REQ/REP exchange (docs/control.md).
  if (std::string e = socket_.open(ZMQ_ROUTER, "ROUTER"); !e.empty()) return e;
  void* router = socket_.get();
  const std::int64_t max_request = kMaxFrameBytes;
  const int zero = 0;
  const int one = 1;
  zmq_setsockopt(router, ZMQ_MAXMSGSIZE, &max_request, sizeof(max_request));
  zmq_setsockopt(router, ZMQ_LINGER, &zero, sizeof(zero));
  // A reply to a peer that has gone, or that never reads its replies (its queue full), fails at
  // once (EHOSTUNREACH/EAGAIN) and is dropped; it never blocks or reaches another peer.
  zmq_setsockopt(router, ZMQ_ROUTER_MANDATORY, &one, sizeof(one));
  zmq_setsockopt(router, ZMQ_HANDSHAKE_IVL, &kHandshakeMs, sizeof(kHandshakeMs));
  // Every connection's coming and going, for the cap and for running out of descriptors: libzmq
  // retries a failed accept() at once, forever (libzmq 4.3 tcp/ipc_listener in_event: "TODO:
  // Handle specific errors like ENFILE/EMFILE"), which was a busy loop; only closing a connection
  // or the listener ends it. The receiving end takes any number of events (RCVHWM 0), so the
  // I/O thread never blocks on them.
  if (zmq_socket_monitor(router, kMonitorEndpoint,
                         ZMQ_EVENT_ACCEPTED | ZMQ_EVENT_ACCEPT_FAILED | ZMQ_EVENT_DISCONNECTED) != 0)
    return "--control: cannot monitor the control socket: " + zmq_error_text();
  monitor_ = zmq_socket(socket_.context(), ZMQ_PAIR);
  const int unlimited = 0;
  if (!monitor_ || zmq_setsockopt(monitor_, ZMQ_RCVHWM, &unlimited, sizeof unlimited) != 0 ||
      zmq_setsockopt(monitor_, ZMQ_LINGER, &zero, sizeof zero) != 0 || zmq_connect(monitor_, kMonitorEndpoint) != 0)
    return "--control: cannot monitor the control socket: " + zmq_error_text();
  max_peers_ = connection_cap(kMinPeers, kMaxPeers);
  if (std::string e = set_curve_server(router, config.curve_secret_key_file, curve_public_); !e.empty()) return e;
  if (!config.curve_allow_dir.empty() && !curve_public_.empty())
    if (std::string e = socket_.allow_only_keys_in(config.curve_allow_dir); !e.empty()) return e;
  return bind_socket(router, config.control_endpoint, "--control", config.allow_remote, !curve_public_.empty(), bound_);
}

void ControlServer::start(ControlTarget& target) {
  if (!enabled()) return;
  stop_.store(false);
  thread_ = std::thread([this, &target] {
    try {
      loop(target);
    } catch (const std::exception& e) {
      spdlog::error("control thread stopped: {} (the pose stream continues)", e.what());
    }
  });
}

void ControlServer::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
  if (monitor_) {
    if (socket_.get()) zmq_socket_monitor(socket_.get(), nullptr, 0);
    zmq_close(monitor_);
    monitor_ = nullptr;
  }
  socket_.close();
}

void ControlServer::on_monitor_event(std::uint16_t event, std::uint32_t value) {
  const int fd = static_cast<int>(value);
  if (event == ZMQ_EVENT_ACCEPTED) {
    peers_[fd] = {Clock::now(), next_order_++};
    backoff_ = std::chrono::milliseconds(100);
    if (peers_.size() > max_peers_) {
      if (!cap_logged_) {
        cap_logged_ = true;
        spdlog::warn("control: {} connections open, the most (a quarter of the free file descriptors, at most {}); "
                     "each new one closes the one idle the longest (logged once)",
                     max_peers_, kMaxPeers);
      }
      evict_idlest();
    }
  } else if (event == ZMQ_EVENT_DISCONNECTED) {
    peers_.erase(fd);
    if (fd == evicting_fd_) evicting_fd_ = -1;
  } else if (event == ZMQ_EVENT_ACCEPT_FAILED && (value == EMFILE || value == ENFILE)) {
    if (!exhaustion_logged_) {
      exhaustion_logged_ = true;
      rlimit limit{};
      ::getrlimit(RLIMIT_NOFILE, &limit);
      spdlog::warn("control: out of file descriptors ({}; the limit is {}, ulimit -n, {} control connections open): "
                   "the idlest control connection is closed to let a new one in, or new connections wait; raise the "
                   "limit if this is not an attack (logged once)",
                   std::strerror(static_cast<int>(value)), static_cast<long long>(limit.rlim_cur), peers_.size());
    }
    if (evicting_fd_ >= 0) return;  // one closing already: its descriptor is the one coming free
    if (!peers_.empty()) {
      evict_idlest();
    } else {
      drop_listener();
    }
  }
}

// Shuts the idlest connection down (libzmq then closes it and reports DISCONNECTED). Only a
// descriptor that is still a socket bound to our endpoint's address family is touched.
void ControlServer::evict_idlest() {
  auto idlest = peers_.end();
  for (auto it = peers_.begin(); it != peers_.end(); ++it) {
    if (it->first == evicting_fd_) continue;
    if (idlest == peers_.end() || it->second.last_active < idlest->second.last_active ||
        (it->second.last_active == idlest->second.last_active && it->second.order < idlest->second.order))
      idlest = it;
  }
  if (idlest == peers_.end()) return;
  const int fd = idlest->first;
  sockaddr_storage local{};
  socklen_t len = sizeof local;
  int type = 0;
  socklen_t type_len = sizeof type;
  const bool ours = ::getsockname(fd, reinterpret_cast<sockaddr*>(&local), &len) == 0 &&
                    ::getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &type_len) == 0 && type == SOCK_STREAM &&
                    (bound_.rfind("ipc://", 0) == 0 ? local.ss_family == AF_UNIX : local.ss_family != AF_UNIX);
  if (!ours) {
    peers_.erase(idlest);  // closed and reused already: its DISCONNECTED is on the way
    return;
  }
  ::shutdown(fd, SHUT_RDWR);
  evicting_fd_ = fd;
}

// Out of descriptors with no connection of ours to close: libzmq would retry accept() at once,
// forever, so the endpoint is unbound and bound again after a back-off (100 ms doubling to 1 s).
// Connected clients keep their connections; new ones (REQ reconnects by itself) wait.
void ControlServer::drop_listener() {
  if (listener_dropped_) return;
  if (zmq_unbind(socket_.get(), bound_.c_str()) != 0) return;
  listener_dropped_ = true;
  rebind_at_ = Clock::now() + backoff_;
  backoff_ = std::min(backoff_ * 2, std::chrono::milliseconds(1000));
}

void ControlServer::retry_listener() {
  if (!listener_dropped_ || Clock::now() < rebind_at_) return;
  if (zmq_bind(socket_.get(), bound_.c_str()) == 0) {
    listener_dropped_ = false;
  } else {
    rebind_at_ = Clock::now() + backoff_;
  }
}

void ControlServer::loop(ControlTarget& target) {
  void* router = socket_.get();
  std::vector<Frame> frames;
  frames.reserve(kMaxFrames);
  while (!stop_.load()) {
    zmq_pollitem_t items[2] = {{router, 0, ZMQ_POLLIN, 0}, {monitor_, 0, ZMQ_POLLIN, 0}};
    // A waiting request is looked at every 10 ms, so its answer leaves soon after it is ready.
    const int ready = zmq_poll(items, monitor_ ? 2 : 1, waiting_.empty() ? 100 : 10);
    retry_listener();
    answer_waiting(/*stopping=*/false);
    if (ready <= 0) continue;
    if (monitor_ && (items[1].revents & ZMQ_POLLIN))
      drain_monitor(monitor_, [this](std::uint16_t event, std::uint32_t value) { on_monitor_event(event, value); });
    if (!(items[0].revents & ZMQ_POLLIN)) continue;
    zmq_msg_t first;
    zmq_msg_init(&first);
    if (zmq_msg_recv(&first, router, ZMQ_DONTWAIT) < 0) {
      zmq_msg_close(&first);
      continue;
    }
    // frames: [peer routing id (ROUTER adds it)] [envelope...] [empty delimiter] [request...]
    int source_fd = -1;
    const bool whole = read_message(router, first, frames, source_fd);
    if (auto peer = peers_.find(source_fd); peer != peers_.end()) peer->second.last_active = Clock::now();
    if (!whole) {
      spdlog::debug("control: dropped a message of more than {} frames", kMaxFrames);
      continue;
    }
    std::size_t delimiter = 1;
    while (delimiter < frames.size() && !frames[delimiter].data.empty()) ++delimiter;
    if (delimiter >= frames.size()) {
      // No delimiter: not a REQ (or REQ-like) request; there is no way to address an answer.
      spdlog::debug("control: dropped a message without a request envelope ({} frames)", frames.size());
      continue;
    }
    const std::size_t body_frames = frames.size() - delimiter - 1;
    ControlReply answer = body_frames != 1 ? ControlReply(control_error("a request is one frame of JSON text"))
                                           : answer_control_request(frames.back().data, target);
    std::vector<std::string> envelope;
    envelope.reserve(delimiter + 1);
    for (std::size_t i = 0; i <= delimiter; ++i) envelope.push_back(std::move(frames[i].data));
    if (answer.later) {
      waiting_.push_back({std::move(envelope), std::move(answer.later)});
      continue;
    }
    send_reply(envelope, answer.reply.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  }
  answer_waiting(/*stopping=*/true);
}

bool ControlServer::send_reply(const std::vector<std::string>& envelope, const std::string& text) {
  void* router = socket_.get();
  // The envelope back as it came, then the reply. If the first frame is refused (peer gone, or
  // its queue full) nothing of this message was queued; later frames then cannot fail.
  bool sent = true;
  for (std::size_t i = 0; i < envelope.size() && sent; ++i)
    sent = zmq_send(router, envelope[i].data(), envelope[i].size(), ZMQ_SNDMORE | ZMQ_DONTWAIT) >= 0;
  if (sent) sent = zmq_send(router, text.data(), text.size(), ZMQ_DONTWAIT) >= 0;
  if (!sent) spdlog::debug("control: reply not sent ({}); the client has gone or does not read", zmq_error_text());
  return sent;
}

void ControlServer::answer_waiting(bool stopping) {
  for (auto it = waiting_.begin(); it != waiting_.end();) {
    std::optional<nlohmann::json> reply;
    try {
      reply = it->later();
    } catch (const std::exception& e) {
      reply = control_error(std::string("internal error: ") + e.what());
    }
    if (!reply && stopping) reply = control_error("bodyd is stopping: the request was not finished");
    if (!reply) {
      ++it;
      continue;
    }
    send_reply(it->envelope, reply->dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
    it = waiting_.erase(it);
  }
}

}  // namespace bodyd::daemon
