#include "bodyd/io/zmq/curve_allow.h"

#include "bodyd/base/log_rate.h"
#include "bodyd/io/zmq/endpoint.h"

#include "bodyd/motion/printable.h"

#include <spdlog/spdlog.h>
#include <zmq.h>

#include <algorithm>
#include <array>

namespace bodyd::daemon {

std::string load_curve_allow_dir(const std::filesystem::path& dir, std::set<std::string>& out_keys,
                                 std::vector<std::string>& out_skipped) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return "--curve-allow " + dir.string() + ": not a directory (a directory of client public keys, NAME.public)";
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir, ec)) files.push_back(entry.path());
  if (ec) return "--curve-allow " + dir.string() + ": cannot list: " + ec.message();
  std::sort(files.begin(), files.end());
  for (const auto& path : files) {
    // A link would admit whatever key it points to, from anywhere (issue 20): refused.
    if (path.extension() == ".public" && fs::is_symlink(fs::symlink_status(path, ec))) {
      const fs::path target = fs::read_symlink(path, ec);
      return "--curve-allow " + dir.string() + ": " + path.filename().string() + " is a symbolic link (to " +
             target.string() + "): refused, as a link admits a key kept elsewhere. Copy the key file itself into " +
             dir.string() + " (cp -L)";
    }
    if (path.extension() != ".public" || !fs::is_regular_file(path, ec)) {
      out_skipped.push_back(path.filename().string());
      continue;
    }
    std::string key;
    if (std::string e = read_curve_key_file(path, key); !e.empty()) return "--curve-allow: " + e;
    out_keys.insert(key);
  }
  if (out_keys.empty())
    return "--curve-allow " + dir.string() +
           ": no client keys (NAME.public files): nobody could connect. Make one with bodyd --gen-keys " + dir.string() +
           " --client NAME";
  return {};
}

namespace {

// One frame of a multipart message; false when there is none.
bool recv_frame(void* socket, std::string& out, bool& more) {
  zmq_msg_t msg;
  zmq_msg_init(&msg);
  if (zmq_msg_recv(&msg, socket, ZMQ_DONTWAIT) < 0) {
    zmq_msg_close(&msg);
    return false;
  }
  out.assign(static_cast<const char*>(zmq_msg_data(&msg)), zmq_msg_size(&msg));
  more = zmq_msg_more(&msg) != 0;
  zmq_msg_close(&msg);
  return true;
}

}  // namespace

std::string ZapAllowList::start(void* zmq_context, std::set<std::string> keys, std::string dir_for_messages) {
  keys_ = std::move(keys);
  dir_ = std::move(dir_for_messages);
  socket_ = zmq_socket(zmq_context, ZMQ_REP);
  if (!socket_) return std::string("ZAP handler: zmq_socket: ") + zmq_strerror(zmq_errno());
  const int zero = 0;
  zmq_setsockopt(socket_, ZMQ_LINGER, &zero, sizeof(zero));
  // The endpoint libzmq asks for every handshake of a socket with a security mechanism.
  if (zmq_bind(socket_, "inproc://zeromq.zap.01") != 0) {
    const std::string e = zmq_strerror(zmq_errno());
    zmq_close(socket_);
    socket_ = nullptr;
    return "ZAP handler: cannot bind inproc://zeromq.zap.01: " + e;
  }
  stop_.store(false);
  thread_ = std::thread([this] { loop(); });
  return {};
}

void ZapAllowList::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
  if (socket_) zmq_close(socket_);
  socket_ = nullptr;
}

void ZapAllowList::loop() {
  while (!stop_.load()) {
    zmq_pollitem_t item{socket_, 0, ZMQ_POLLIN, 0};
    if (zmq_poll(&item, 1, 100) <= 0) continue;
    // RFC 27 request: version, request id, domain, address, routing id, mechanism, credentials...
    std::vector<std::string> frames;
    std::string frame;
    bool more = true;
    while (more && recv_frame(socket_, frame, more)) frames.push_back(frame);
    if (frames.empty()) continue;
    const std::string request_id = frames.size() > 1 ? frames[1] : std::string();
    std::string status = "400", text = "refused", user;
    if (frames.size() < 7 || frames[0] != "1.0") {
      status = "500";
      text = "malformed ZAP request";
      spdlog::error("CURVE allow-list: a malformed ZAP request ({} frames); refused", frames.size());
    } else if (frames[5] != "CURVE" || frames[6].size() != 32) {
      text = "only CURVE clients with a listed key";
    } else {
      char z85[41] = {};
      zmq_z85_encode(z85, reinterpret_cast<const std::uint8_t*>(frames[6].data()), 32);
      if (keys_.count(z85)) {
        status = "200";
        text = "OK";
        user = z85;
        accepted_.fetch_add(1);
        spdlog::debug("CURVE allow-list: accepted client {} from {}", z85, printable(frames[3], 64));
      } else {
        const std::uint64_t n = refused_.fetch_add(1) + 1;
        text = "client key not allowed";
        // A client retrying every few ms, or many made-up keys, must not flood the log (issue 20):
        // each of the first kLoggedKeys keys once, and then the 1st, 2nd, 4th, 8th... refusal.
        const bool new_key = refused_logged_.size() < kLoggedKeys && refused_logged_.insert(z85).second;
        if (new_key || log_occurrence(n))
          spdlog::warn("CURVE allow-list: refused client key {} from {} (not in --curve-allow {}; add its .public file "
                       "there and restart bodyd to let it in; {} refused so far, logged at a limited rate)",
                       z85, printable(frames[3], 64), dir_, n);
      }
    }
    const std::array<std::string, 6> reply{"1.0", request_id, status, text, user, ""};
    for (std::size_t i = 0; i < reply.size(); ++i)
      zmq_send(socket_, reply[i].data(), reply[i].size(), i + 1 < reply.size() ? ZMQ_SNDMORE : 0);
  }
}

}  // namespace bodyd::daemon
