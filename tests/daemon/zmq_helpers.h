// Small helpers for daemon tests: a pose subscriber, control requests, the daemon as a child
// process (on the test-support library's Process, TempDir and read_file).
#pragma once

#include "bodyd/motion/rotation.h"
#include "bodyd/protocol/pose_message.h"
#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

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

// Receives skeleton and poses until `done` says so (checked after each message and when
// nothing arrives for 100 ms).
template <typename Done>
void collect(zmq::socket_t& sub, protocol::SkeletonMessage& skeleton, std::vector<protocol::PoseMessage>& poses, Done done) {
  for (bool first = true;; first = false) {
    if (!first && done()) return;
    zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
    if (zmq::poll(&item, 1, std::chrono::milliseconds(100)) == 0) {
      if (done()) return;
      continue;
    }
    zmq::message_t topic, payload;
    if (!sub.recv(topic, zmq::recv_flags::dontwait) || !topic.more()) continue;
    (void)sub.recv(payload);
    const auto* p = static_cast<const std::uint8_t*>(payload.data());
    const std::vector<std::uint8_t> bytes(p, p + payload.size());
    if (topic.to_string_view() == protocol::kSkeletonTopic) {
      ASSERT_TRUE(protocol::decode_skeleton(bytes, skeleton).ok());
    } else if (topic.to_string_view() == protocol::kPoseTopic) {
      protocol::PoseMessage pose;
      ASSERT_TRUE(protocol::decode_pose(bytes, pose).ok());
      poses.push_back(pose);
    }
  }
}

// After a recenter (issue 45 item 3): an output that publishes in the runtime's space sends the
// ZeroMQ poses (the user's re-centred space) taken back through the re-centring that `status`
// reports, p = R^-1 p' + origin, q = R^-1 q', R the turn by -heading_deg about +Y
// (docs/control.md). The poses as that output sends them: those before the recenter (the first
// `before`) as they are; the next `in_flight` both as they are and taken back (made while the
// recenter was on its way); every later one taken back. `from[i]`: the index in `poses` of the
// i-th pose returned.
struct RuntimeSpacePoses {
  std::vector<protocol::PoseMessage> poses;
  std::vector<std::size_t> from;
  double heading_rad = 0.0;
  Vec3 origin_m = Vec3::Zero();
};
inline RuntimeSpacePoses in_runtime_space(const std::vector<protocol::PoseMessage>& poses, std::size_t before,
                                          const nlohmann::json& status, std::size_t in_flight = 30) {
  RuntimeSpacePoses out;
  out.heading_rad = status["recentre"]["heading_deg"].get<double>() * M_PI / 180.0;
  out.origin_m = Vec3(status["recentre"]["origin_m"][0].get<double>(), 0.0, status["recentre"]["origin_m"][1].get<double>());
  const Quat r(Eigen::AngleAxisd(-out.heading_rad, Vec3::UnitY()));
  for (std::size_t i = 0; i < poses.size(); ++i) {
    if (i < before + in_flight) {
      out.poses.push_back(poses[i]);
      out.from.push_back(i);
    }
    if (i < before) continue;
    out.poses.push_back(poses[i]);
    out.from.push_back(i);
    for (auto& j : out.poses.back().joints) {
      const Vec3 p = r.conjugate() * Vec3(j.position_m[0], j.position_m[1], j.position_m[2]) + out.origin_m;
      const Quat q = (r.conjugate() * Quat(j.rotation_xyzw[3], j.rotation_xyzw[0], j.rotation_xyzw[1], j.rotation_xyzw[2]))
                         .normalized();
      j.position_m = {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())};
      j.rotation_xyzw = {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()), static_cast<float>(q.w())};
    }
  }
  return out;
}

// collect() until `feeder` has exited and no pose came for 500 ms.
inline void collect_until_quiet(zmq::socket_t& sub, protocol::SkeletonMessage& skeleton,
                                std::vector<protocol::PoseMessage>& poses, Process& feeder) {
  auto quiet_since = std::chrono::steady_clock::now();
  std::size_t last = 0;
  collect(sub, skeleton, poses, [&] {
    if (poses.size() != last) last = poses.size(), quiet_since = std::chrono::steady_clock::now();
    return feeder.wait(0).has_value() && std::chrono::steady_clock::now() - quiet_since > std::chrono::milliseconds(500);
  });
}

// The program `name` on PATH (the first executable one), or "".
inline std::string find_on_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::stringstream ss(path ? path : "");
  std::string dir;
  while (std::getline(ss, dir, ':'))
    if (!dir.empty() && ::access((std::filesystem::path(dir) / name).c_str(), X_OK) == 0)
      return (std::filesystem::path(dir) / name).string();
  return {};
}

// A child process with its stderr in a file (stdout dropped); log() is its stderr.
class Child : public Process {
 public:
  Child(const std::vector<std::string>& args, const std::filesystem::path& stderr_path)
      : Process(args, {.stdout_path = "/dev/null", .stderr_path = stderr_path}) {}
  std::string log() const { return err(); }
};

// Waits for the daemon's --endpoints-file; nullopt after timeout_ms.
inline std::optional<nlohmann::json> wait_endpoints(const std::filesystem::path& file, int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    auto j = nlohmann::json::parse(read_file(file), nullptr, false);
    if (!j.is_discarded()) return j;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return std::nullopt;
}

// Once a daemon started with --endpoints-file `endpoints_file` has written it (within 20 s):
// `sub` subscribed to its pub endpoint, given 300 ms for the subscription to reach the publisher.
// The failure, when the file did not come, is the daemon's log.
inline ::testing::AssertionResult subscribe_when_up(zmq::context_t& ctx, const std::filesystem::path& endpoints_file,
                                                    const Child& daemon, zmq::socket_t& sub) {
  const auto endpoints = wait_endpoints(endpoints_file, 20000);
  if (!endpoints) return ::testing::AssertionFailure() << daemon.log();
  sub = sub_socket(ctx, (*endpoints)["pub"].get<std::string>());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the subscription reaches the publisher
  return ::testing::AssertionSuccess();
}

}  // namespace bodyd::test
