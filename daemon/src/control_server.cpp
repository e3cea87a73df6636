#include "control_server.h"

#include "bodyd/daemon/config.h"

#include <spdlog/spdlog.h>
#include <zmq.h>

#include <string>
#include <vector>

namespace bodyd::daemon {

namespace {

// A request is a few bytes; refuse floods.
constexpr std::int64_t kMaxFrameBytes = 64 * 1024;
// A REQ client's envelope is its routing id and an empty delimiter; REQ/ROUTER chains add one
// frame per hop. A message with more frames than this is no request and is dropped unanswered.
constexpr std::size_t kMaxFrames = 32;

struct Frame {
  std::string data;
};

// Reads the rest of one message (every part is there once the first is: ZeroMQ delivers whole
// messages). Keeps at most kMaxFrames frames; returns false when there were more (the message
// is drained all the same).
bool read_message(void* socket, zmq_msg_t& first, std::vector<Frame>& out) {
  out.clear();
  bool within_limit = true;
  zmq_msg_t msg;
  zmq_msg_init(&msg);
  zmq_msg_move(&msg, &first);
  for (;;) {
    if (out.size() < kMaxFrames)
      out.push_back({std::string(static_cast<const char*>(zmq_msg_data(&msg)), zmq_msg_size(&msg))});
    else
      within_limit = false;
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
  socket_.close();
}

void ControlServer::loop(ControlTarget& target) {
  void* router = socket_.get();
  std::vector<Frame> frames;
  frames.reserve(kMaxFrames);
  while (!stop_.load()) {
    zmq_pollitem_t item{router, 0, ZMQ_POLLIN, 0};
    if (zmq_poll(&item, 1, 100) <= 0) continue;
    zmq_msg_t first;
    zmq_msg_init(&first);
    if (zmq_msg_recv(&first, router, ZMQ_DONTWAIT) < 0) {
      zmq_msg_close(&first);
      continue;
    }
    // frames: [peer routing id (ROUTER adds it)] [envelope...] [empty delimiter] [request...]
    if (!read_message(router, first, frames)) {
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
    const nlohmann::json reply = body_frames != 1 ? control_error("a request is one frame of JSON text")
                                                  : handle_control_request(frames.back().data, target);
    const std::string text = reply.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    // The envelope back as it came, then the reply. If the first frame is refused (peer gone, or
    // its queue full) nothing of this message was queued; later frames then cannot fail.
    bool sent = true;
    for (std::size_t i = 0; i <= delimiter && sent; ++i)
      sent = zmq_send(router, frames[i].data.data(), frames[i].data.size(), ZMQ_SNDMORE | ZMQ_DONTWAIT) >= 0;
    if (sent) sent = zmq_send(router, text.data(), text.size(), ZMQ_DONTWAIT) >= 0;
    if (!sent) spdlog::debug("control: reply not sent ({}); the client has gone or does not read", zmq_error_text());
  }
}

}  // namespace bodyd::daemon
