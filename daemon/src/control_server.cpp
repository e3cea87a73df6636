#include "control_server.h"

#include "bodyd/daemon/config.h"

#include <spdlog/spdlog.h>
#include <zmq.h>

namespace bodyd::daemon {

std::string ControlServer::open(const DaemonConfig& config) {
  if (config.control_endpoint.empty() || config.control_endpoint == "none") return {};
  if (std::string e = socket_.open(ZMQ_REP, "REP"); !e.empty()) return e;
  void* rep = socket_.get();
  const std::int64_t max_request = 64 * 1024;  // a request is a few bytes; refuse floods
  const int zero = 0;
  zmq_setsockopt(rep, ZMQ_MAXMSGSIZE, &max_request, sizeof(max_request));
  zmq_setsockopt(rep, ZMQ_LINGER, &zero, sizeof(zero));
  if (std::string e = set_curve_server(rep, config.curve_secret_key_file, curve_public_); !e.empty()) return e;
  if (!config.curve_allow_dir.empty() && !curve_public_.empty())
    if (std::string e = socket_.allow_only_keys_in(config.curve_allow_dir); !e.empty()) return e;
  return bind_socket(rep, config.control_endpoint, "--control", config.allow_remote, !curve_public_.empty(), bound_);
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
  void* rep = socket_.get();
  while (!stop_.load()) {
    zmq_pollitem_t item{rep, 0, ZMQ_POLLIN, 0};
    if (zmq_poll(&item, 1, 100) <= 0) continue;
    zmq_msg_t msg;
    zmq_msg_init(&msg);
    const int n = zmq_msg_recv(&msg, rep, ZMQ_DONTWAIT);
    if (n < 0) {
      zmq_msg_close(&msg);
      continue;
    }
    std::string request(static_cast<const char*>(zmq_msg_data(&msg)), zmq_msg_size(&msg));
    // Drain further frames of a multipart request; only a single frame is a valid request.
    bool multipart = false;
    while (zmq_msg_more(&msg)) {
      multipart = true;
      zmq_msg_close(&msg);
      zmq_msg_init(&msg);
      if (zmq_msg_recv(&msg, rep, 0) < 0) break;
    }
    zmq_msg_close(&msg);
    const nlohmann::json reply =
        multipart ? control_error("a request is one frame of JSON text") : handle_control_request(request, target);
    const std::string text = reply.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    if (zmq_send(rep, text.data(), text.size(), 0) < 0) spdlog::warn("control: cannot send the reply: {}", zmq_error_text());
  }
}

}  // namespace bodyd::daemon
