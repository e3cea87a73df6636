// Small helpers for daemon tests: a pose subscriber, control requests, child processes.
#pragma once

#include "bodyd/protocol/pose_message.h"

#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace bodyd::test {

// Receives the next message of `topic` (skipping others) within `timeout_ms`; nullopt on timeout.
inline std::optional<std::vector<std::uint8_t>> recv_topic(zmq::socket_t& sub, std::string_view topic, int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return std::nullopt;
    zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
    if (zmq::poll(&item, 1, left) == 0) continue;
    zmq::message_t t, m;
    if (!sub.recv(t, zmq::recv_flags::dontwait)) continue;
    if (!t.more()) continue;
    (void)sub.recv(m);
    while (m.more()) (void)sub.recv(m);
    if (t.to_string_view() != topic) continue;
    const auto* p = static_cast<const std::uint8_t*>(m.data());
    return std::vector<std::uint8_t>(p, p + m.size());
  }
}

inline std::optional<protocol::PoseMessage> recv_pose(zmq::socket_t& sub, int timeout_ms) {
  auto bytes = recv_topic(sub, protocol::kPoseTopic, timeout_ms);
  if (!bytes) return std::nullopt;
  protocol::PoseMessage pose;
  if (auto s = protocol::decode_pose(*bytes, pose); !s.ok()) throw std::runtime_error("bad pose: " + s.error);
  return pose;
}

// A SUB socket connected to `endpoint`, subscribed to `topic` ("": every message), no linger.
inline zmq::socket_t sub_socket(zmq::context_t& ctx, const std::string& endpoint, const std::string& topic = "") {
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, 0);  // a test that reads slowly must not lose poses
  sub.set(zmq::sockopt::subscribe, topic);
  sub.connect(endpoint);
  return sub;
}

// One control request (fresh REQ socket); nullopt when no reply within timeout_ms.
inline std::optional<nlohmann::json> control_request(zmq::context_t& ctx, const std::string& endpoint,
                                                     const std::string& request, int timeout_ms = 3000) {
  zmq::socket_t req(ctx, zmq::socket_type::req);
  req.set(zmq::sockopt::linger, 0);
  req.set(zmq::sockopt::rcvtimeo, timeout_ms);
  req.connect(endpoint);
  req.send(zmq::buffer(request));
  zmq::message_t reply;
  if (!req.recv(reply)) return std::nullopt;
  return nlohmann::json::parse(reply.to_string());
}

// A child process with its stderr in a file.
class Child {
 public:
  Child(const std::vector<std::string>& args, const std::filesystem::path& stderr_path) {
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 2, stderr_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    if (posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&actions);
    stderr_path_ = stderr_path;
  }
  ~Child() {
    if (pid_ > 0 && !exit_code_) {
      kill(pid_, SIGKILL);
      int status = 0;
      waitpid(pid_, &status, 0);
    }
  }
  bool running() const { return pid_ > 0 && !exit_code_; }
  pid_t pid() const { return pid_; }
  void signal(int sig) const {
    if (pid_ > 0 && !exit_code_) kill(pid_, sig);
  }
  // Exit code (128+signal when killed), or nullopt if still running after timeout_ms.
  std::optional<int> wait(int timeout_ms) {
    if (exit_code_) return exit_code_;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
      int status = 0;
      const pid_t r = waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        return exit_code_;
      }
      if (std::chrono::steady_clock::now() > deadline) return std::nullopt;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  std::string log() const {
    std::ifstream in(stderr_path_);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

 private:
  pid_t pid_ = -1;
  std::optional<int> exit_code_;
  std::filesystem::path stderr_path_;
};

// Waits for the daemon's --endpoints-file; nullopt after timeout_ms.
inline std::optional<nlohmann::json> wait_endpoints(const std::filesystem::path& file, int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    std::ifstream in(file);
    if (in) {
      std::stringstream ss;
      ss << in.rdbuf();
      auto j = nlohmann::json::parse(ss.str(), nullptr, false);
      if (!j.is_discarded()) return j;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return std::nullopt;
}

// A fresh temporary directory, removed at destruction.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "bodyd-test-XXXXXX").string();
    path = mkdtemp(tmpl.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

}  // namespace bodyd::test
