// bodyd-sub: subscribe to bodyd's pose stream and print it.
//
//   bodyd-sub --endpoint E [--control C] [--count N] [--json [--rotations]] [--wait-skeleton]
//             [--timeout-s S]
//
// With --json, one JSON object per pose and line (client::pose_to_json); otherwise a live
// one-line summary once a second: receive rate, latencies, sequence gaps.
// Exit status: 0 done (count reached or interrupted), 1 error, 2 no pose within --timeout-s.
#include "bodyd/base/clock.h"
#include "bodyd/base/percentile.h"
#include "bodyd/client/client.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <span>
#include <vector>

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop = true; }

// Nearest rank (bodyd/base/percentile.h), in ms; 0 for a second without poses.
double percentile_ms(std::vector<std::int64_t>& values_ns, double p) {
  return static_cast<double>(bodyd::percentile(std::span<std::int64_t>(values_ns), p).value_or(0)) / 1e6;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Subscribe to bodyd's pose stream and print poses (docs/protocol.md)."};
  bodyd::client::ClientOptions options;
  options.control_endpoint.clear();
  std::uint64_t count = 0;
  bool json = false;
  bool rotations = false;
  bool wait_skeleton = false;
  double timeout_s = 0.0;
  app.add_option("--endpoint,-e", options.pose_endpoint, "pose stream (PUB) endpoint to connect to")
      ->capture_default_str();
  app.add_option("--control,-c", options.control_endpoint,
                 "control endpoint to ask for the skeleton at start (optional; the stream also carries it)");
  app.add_option("--count,-n", count, "exit after N poses (0: run until interrupted)");
  app.add_flag("--json", json, "print one JSON object per pose and line");
  app.add_flag("--rotations", rotations, "with --json, also print joint rotations (x, y, z, w)");
  app.add_flag("--wait-skeleton", wait_skeleton,
               "skip poses until the skeleton is known (it comes once a second), so --json always names joints");
  app.add_option("--timeout-s", timeout_s, "exit with status 2 when no pose arrives for this long (0: wait forever)")
      ->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);

  std::string error;
  auto client = bodyd::client::Client::connect(options, error);
  if (!client) {
    fmt::print(stderr, "bodyd-sub: {}\n", error);
    return 1;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::signal(SIGPIPE, SIG_IGN);

  if (!options.control_endpoint.empty()) {
    bodyd::protocol::SkeletonMessage skeleton;
    if (auto s = client->skeleton(skeleton); !s) {
      fmt::print(stderr, "bodyd-sub: warning: {} (joint names come with the next skeleton message)\n", s.error);
    }
  }

  const bool tty = isatty(STDOUT_FILENO) != 0;
  bodyd::protocol::PoseMessage pose;
  std::uint64_t received = 0;
  std::int64_t last_pose_ns = bodyd::monotonic_ns();
  std::int64_t window_start_ns = last_pose_ns;
  std::uint64_t window_poses = 0;
  std::vector<std::int64_t> pipeline_ns, transport_ns;
  std::string last_malformed;
  while (!g_stop && (count == 0 || received < count)) {
    const auto result = client->receive(pose, std::chrono::milliseconds(100));
    const std::int64_t now_ns = bodyd::monotonic_ns();
    if (result == bodyd::client::Received::kError) {
      fmt::print(stderr, "bodyd-sub: {}\n", client->error());
      return 1;
    }
    if (result == bodyd::client::Received::kMalformed) {
      if (client->error() != last_malformed) fmt::print(stderr, "bodyd-sub: skipped a message: {}\n", client->error());
      last_malformed = client->error();
    }
    if (result == bodyd::client::Received::kPose && wait_skeleton &&
        (!client->current_skeleton() || client->current_skeleton()->skeleton_id != pose.skeleton_id)) {
      last_pose_ns = now_ns;
      continue;
    }
    if (result == bodyd::client::Received::kPose) {
      ++received;
      ++window_poses;
      last_pose_ns = now_ns;
      if (json) {
        const auto& sk = client->current_skeleton();
        const std::string line = bodyd::client::pose_to_json(pose, sk ? &*sk : nullptr, rotations).dump();
        std::fwrite(line.data(), 1, line.size(), stdout);
        std::fputc('\n', stdout);
        std::fflush(stdout);
      } else {
        pipeline_ns.push_back(pose.publish_t_ns - pose.t_ns);
        transport_ns.push_back(now_ns - pose.publish_t_ns);
      }
    } else if (timeout_s > 0 && static_cast<double>(now_ns - last_pose_ns) > timeout_s * 1e9) {
      fmt::print(stderr, "bodyd-sub: no pose from {} for {} s (is bodyd running and publishing there?)\n",
                 options.pose_endpoint, timeout_s);
      return 2;
    }
    if (!json && (now_ns - window_start_ns >= 1'000'000'000 || (count && received == count))) {
      const double dt_s = static_cast<double>(now_ns - window_start_ns) / 1e9;
      const auto& st = client->stats();
      // Latencies compare the publisher's CLOCK_MONOTONIC with ours: meaningful on one machine.
      const std::string line = fmt::format(
          "{:7.1f} Hz | publish-sample p50 {:.2f} p99 {:.2f} ms | recv-publish p50 {:.2f} p99 {:.2f} ms | "
          "seq {} | dropped {} | malformed {} | restarts {}",
          dt_s > 0 ? static_cast<double>(window_poses) / dt_s : 0.0, percentile_ms(pipeline_ns, 0.5),
          percentile_ms(pipeline_ns, 0.99), percentile_ms(transport_ns, 0.5), percentile_ms(transport_ns, 0.99),
          received ? std::to_string(pose.seq) : std::string("-"), st.dropped, st.malformed, st.restarts);
      if (tty) fmt::print("\r{}\x1b[K", line);
      else fmt::print("{}\n", line);
      std::fflush(stdout);
      window_start_ns = now_ns;
      window_poses = 0;
      pipeline_ns.clear();
      transport_ns.clear();
    }
  }
  if (!json && tty) fmt::print("\n");
  const auto& st = client->stats();
  fmt::print(stderr, "bodyd-sub: {} poses, {} dropped (seq gaps), {} malformed, {} restarts\n", st.poses, st.dropped,
             st.malformed, st.restarts);
  return 0;
}
