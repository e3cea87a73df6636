// bodyd-testpub: publish the synthetic pose stream (protocol/synthetic.h) like bodyd does,
// without trackers or a model; for demos and for testing subscribers.
//
//   bodyd-testpub [--endpoint tcp://127.0.0.1:*] [--count N] [--rate-hz R] [--wait-subscriber]
//
// Prints the bound endpoint (ZMQ_LAST_ENDPOINT, useful with a "*" port) as the first line of
// stdout. Publishes the skeleton first and once a second, like the daemon.
#include "bodyd/base/clock.h"
#include "bodyd/protocol/synthetic.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <zmq.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <thread>

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop = true; }

void send(zmq::socket_t& socket, std::string_view topic, const std::vector<std::uint8_t>& frame) {
  socket.send(zmq::buffer(topic), zmq::send_flags::sndmore);
  socket.send(zmq::buffer(frame), zmq::send_flags::none);
}

}  // namespace

int main(int argc, char** argv) {
  namespace protocol = bodyd::protocol;
  CLI::App app{"Publish a synthetic pose stream in bodyd's wire protocol (docs/protocol.md)."};
  std::string endpoint = "tcp://127.0.0.1:*";
  std::uint64_t count = 0;
  double rate_hz = 90.0;
  bool wait_subscriber = false;
  app.add_option("--endpoint,-e", endpoint, "endpoint to bind (a \"*\" port is chosen by the OS)")
      ->capture_default_str();
  app.add_option("--count,-n", count, "poses to publish, then exit (0: until interrupted)");
  app.add_option("--rate-hz", rate_hz, "poses per second")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_flag("--wait-subscriber", wait_subscriber,
               "start publishing only once a subscriber has subscribed (no lost first messages)");
  CLI11_PARSE(app, argc, argv);

  zmq::context_t context{1};
  zmq::socket_t pub{context, zmq::socket_type::xpub};  // XPUB: sees subscriptions
  try {
    pub.set(zmq::sockopt::linger, 1000);
    pub.bind(endpoint);
  } catch (const zmq::error_t& e) {
    fmt::print(stderr, "bodyd-testpub: cannot bind \"{}\": {} (port in use? try tcp://127.0.0.1:*)\n", endpoint,
               e.what());
    return 1;
  }
  fmt::print("{}\n", pub.get(zmq::sockopt::last_endpoint));
  std::fflush(stdout);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  const auto drain_subscriptions = [&](int timeout_ms) {
    bool any = false;
    zmq::message_t msg;
    pub.set(zmq::sockopt::rcvtimeo, timeout_ms);
    while (pub.recv(msg, zmq::recv_flags::none)) {
      any = true;
      pub.set(zmq::sockopt::rcvtimeo, 0);
    }
    return any;
  };
  if (wait_subscriber) {
    while (!g_stop && !drain_subscriptions(100)) {
    }
  }

  std::vector<std::uint8_t> skeleton_frame, pose_frame;
  const protocol::SkeletonMessage skeleton = protocol::synthetic_skeleton();
  if (auto s = protocol::encode_skeleton(skeleton, skeleton_frame); !s) {
    fmt::print(stderr, "bodyd-testpub: {}\n", s.error);
    return 1;
  }
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / rate_hz));
  const std::int64_t start_ns = bodyd::monotonic_ns();
  auto next = std::chrono::steady_clock::now();
  auto next_skeleton = next;
  for (std::uint64_t seq = 0; !g_stop && (count == 0 || seq < count); ++seq) {
    drain_subscriptions(0);
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_skeleton) {
      send(pub, protocol::kSkeletonTopic, skeleton_frame);
      next_skeleton = now + std::chrono::seconds(1);
    }
    protocol::PoseMessage pose = protocol::synthetic_pose(seq, start_ns, period.count());
    pose.publish_t_ns = bodyd::monotonic_ns();
    if (auto s = protocol::encode_pose(pose, pose_frame); !s) {
      fmt::print(stderr, "bodyd-testpub: {}\n", s.error);
      return 1;
    }
    send(pub, protocol::kPoseTopic, pose_frame);
    next += period;
    std::this_thread::sleep_until(next);
  }
  return 0;
}
