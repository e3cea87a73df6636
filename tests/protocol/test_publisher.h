// In-process stand-ins for the daemon's sockets, for end-to-end tests of subscribers:
// a publisher of the synthetic stream and a control (REP) server answering "skeleton".
#pragma once

#include "bodyd/client/client.h"
#include "bodyd/protocol/synthetic.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"

#include <zmq.hpp>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

namespace bodyd::test {

// A fresh ipc:// endpoint in a directory of its own, removed when the test process exits.
inline std::string ipc_endpoint(const std::string& name) {
  static std::vector<std::unique_ptr<TempDir>> dirs;
  dirs.push_back(std::make_unique<TempDir>("bodyd-test"));
  return "ipc://" + (dirs.back()->path / name).string();
}

// Binds an XPUB socket (tcp://127.0.0.1:* unless told otherwise), waits until a subscriber
// has subscribed (so nothing is lost to the slow-joiner effect), then publishes the synthetic
// stream: the skeleton every `skeleton_period`, a pose every `pose_period`, seq from 0, until
// stopped or max_poses were sent. Frames from `raw_before` (topic, bytes, frame count) are
// sent first, to test malformed input.
class TestPublisher {
 public:
  struct Options {
    std::string endpoint = "tcp://127.0.0.1:*";
    std::chrono::microseconds pose_period{2000};
    std::chrono::microseconds skeleton_period{20000};
    std::uint64_t max_poses = 1'000'000;
    bool send_skeleton = true;
    std::function<void(zmq::socket_t&)> before_poses;  // e.g. send malformed messages
  };

  explicit TestPublisher(Options options) : options_(std::move(options)), socket_(context_, zmq::socket_type::xpub) {
    socket_.set(zmq::sockopt::linger, 0);
    socket_.bind(options_.endpoint);
    endpoint_ = socket_.get(zmq::sockopt::last_endpoint);
    thread_ = std::thread([this] { run(); });
  }
  TestPublisher() : TestPublisher(Options{}) {}
  ~TestPublisher() { stop(); }

  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  [[nodiscard]] const std::string& endpoint() const { return endpoint_; }
  [[nodiscard]] std::uint64_t poses_sent() const { return sent_; }

 private:
  void run() {
    zmq::message_t sub;
    socket_.set(zmq::sockopt::rcvtimeo, 10);
    while (!stop_ && !socket_.recv(sub, zmq::recv_flags::none)) {
    }
    socket_.set(zmq::sockopt::rcvtimeo, 0);
    if (options_.before_poses) options_.before_poses(socket_);
    std::vector<std::uint8_t> skeleton, pose;
    (void)protocol::encode_skeleton(protocol::synthetic_skeleton(), skeleton);
    auto next_skeleton = std::chrono::steady_clock::now();
    for (std::uint64_t seq = 0; !stop_ && seq < options_.max_poses; ++seq) {
      while (socket_.recv(sub, zmq::recv_flags::dontwait)) {  // later subscriptions
      }
      if (options_.send_skeleton && std::chrono::steady_clock::now() >= next_skeleton) {
        socket_.send(zmq::buffer(protocol::kSkeletonTopic), zmq::send_flags::sndmore);
        socket_.send(zmq::buffer(skeleton), zmq::send_flags::none);
        next_skeleton += options_.skeleton_period;
      }
      (void)protocol::encode_pose(protocol::synthetic_pose(seq), pose);
      socket_.send(zmq::buffer(protocol::kPoseTopic), zmq::send_flags::sndmore);
      socket_.send(zmq::buffer(pose), zmq::send_flags::none);
      sent_ = seq + 1;
      std::this_thread::sleep_for(options_.pose_period);
    }
  }

  Options options_;
  zmq::context_t context_{1};
  zmq::socket_t socket_;
  std::string endpoint_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> sent_{0};
};

// A REP socket answering {"cmd":"skeleton"} with the synthetic skeleton and anything else with
// {"ok":false,"error":...}, as docs/control.md describes the daemon's replies.
class TestControlServer {
 public:
  explicit TestControlServer(const std::string& endpoint = "tcp://127.0.0.1:*",
                             protocol::SkeletonMessage skeleton = protocol::synthetic_skeleton())
      : skeleton_(std::move(skeleton)), socket_(context_, zmq::socket_type::rep) {
    socket_.set(zmq::sockopt::linger, 0);
    socket_.bind(endpoint);
    endpoint_ = socket_.get(zmq::sockopt::last_endpoint);
    thread_ = std::thread([this] { run(); });
  }
  ~TestControlServer() {
    stop_ = true;
    thread_.join();
  }
  [[nodiscard]] const std::string& endpoint() const { return endpoint_; }
  [[nodiscard]] int requests() const { return requests_; }

 private:
  void run() {
    socket_.set(zmq::sockopt::rcvtimeo, 10);
    zmq::message_t msg;
    while (!stop_) {
      if (!socket_.recv(msg, zmq::recv_flags::none)) continue;
      ++requests_;
      const auto request = nlohmann::json::parse(msg.to_string_view(), nullptr, false);
      nlohmann::json reply;
      if (request.is_object() && request.value("cmd", "") == "skeleton") {
        reply = client::skeleton_to_json(skeleton_);
        reply["ok"] = true;
      } else {
        reply = {{"ok", false}, {"error", "unknown command"}};
      }
      const std::string text = reply.dump();
      socket_.send(zmq::buffer(text), zmq::send_flags::none);
    }
  }

  protocol::SkeletonMessage skeleton_;
  zmq::context_t context_{1};
  zmq::socket_t socket_;
  std::string endpoint_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<int> requests_{0};
};

inline std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  while (start < text.size()) {
    const std::size_t end = text.find('\n', start);
    lines.push_back(text.substr(start, end == std::string::npos ? std::string::npos : end - start));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return lines;
}

}  // namespace bodyd::test
