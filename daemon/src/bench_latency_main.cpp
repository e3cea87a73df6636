// bodyd-bench-latency: the daemon's latency and CPU use (docs/daemon.md, "Benchmark").
//
// Runs the real pipeline in-process (a paced replay source -> queue -> reconstruction ->
// ZeroMQ PUB send) on a tracker log at its recorded rate, looping it until enough poses were
// published, and reports per pose: the time from the head sample's arrival in the daemon
// (pushed into the queue by its source) to the pose's publication (zmq_send returned), its
// parts (queue wait, reconstruction, encode + send), and the process's CPU time (getrusage)
// over the run as a percentage of one core. Not a test: numbers depend on the machine.
// With --output SPEC (repeatable; docs/outputs.md) the poses also go to those outputs, and
// two more rows say what they add: arrival -> every output sent, and the outputs' own time
// after the --pub send. --udp-sink PORT binds 127.0.0.1:PORT (UDP) and never reads it, so an
// OSC output has a receiver (no ICMP "port unreachable") that costs this process nothing.
// --stalled-subscriber connects a pose subscriber that never reads (receive queue of one pose),
// so the rows say what a stalled client costs each pose (Pipeline.AStalledSubscriberDoesNotSlowTheDaemon
// checks that the daemon never waits for one).
#include "bodyd/base/percentile.h"
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/daemon.h"
#include "bodyd/daemon/reconstructors.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <zmq.h>

#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <span>
#include <thread>
#include <vector>

namespace {

volatile std::sig_atomic_t g_stop = 0;
extern "C" void on_signal(int) { g_stop = 1; }

double cpu_seconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  auto seconds = [](const timeval& t) { return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_usec) / 1e6; };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

struct Percentiles {
  double p50 = 0, p90 = 0, p99 = 0, max = 0, mean = 0;
};

Percentiles percentiles_us(std::vector<std::int64_t> v_ns) {
  Percentiles p;
  if (v_ns.empty()) return p;
  std::sort(v_ns.begin(), v_ns.end());
  // Nearest rank (bodyd/base/percentile.h); all zero without values (above).
  auto at = [&](double q) {
    return static_cast<double>(*bodyd::percentile_of_sorted(std::span<const std::int64_t>(v_ns), q)) / 1e3;
  };
  p.p50 = at(0.5), p.p90 = at(0.9), p.p99 = at(0.99), p.max = static_cast<double>(v_ns.back()) / 1e3;
  double sum = 0;
  for (auto x : v_ns) sum += static_cast<double>(x);
  p.mean = sum / static_cast<double>(v_ns.size()) / 1e3;
  return p;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace bodyd::daemon;
  CLI::App app{"bodyd-bench-latency: sample-arrival-to-publication latency and CPU use of the bodyd pipeline"};
  std::string replay = bundled_recording_path().string();
  std::string method = "diffusion", model, skeleton;
  int frames = 3000, warmup = 30;
  double speed = 1.0;
  bool json_out = false, stalled_subscriber = false;
  std::vector<std::string> outputs;
  std::vector<int> udp_sinks;
  app.add_option("--replay", replay, "tracker log to replay, paced, in a loop (default: the bundled recording)");
  app.add_option("--method", method, "diffusion (falls back to ik if the default model is missing) or ik");
  app.add_option("--model", model, "model file for diffusion");
  app.add_option("--skeleton", skeleton, "BVH skeleton for ik (default: bundled)");
  app.add_option("--frames", frames, "poses to measure (at 90 Hz, 3000 take 33 s)")->check(CLI::PositiveNumber);
  app.add_option("--warmup", warmup, "poses to skip first")->check(CLI::NonNegativeNumber);
  app.add_option("--speed", speed, "replay speed factor (1: the recorded rate)")->check(CLI::PositiveNumber);
  app.add_flag("--json", json_out, "print the results as one JSON object");
  app.add_option("--output", outputs, "also send every pose to this output (bodyd --output SPEC), repeatable");
  app.add_option("--udp-sink", udp_sinks, "bind UDP 127.0.0.1:PORT and never read it (a receiver for an OSC output)")
      ->check(CLI::Range(1, 65535));
  app.add_flag("--stalled-subscriber", stalled_subscriber, "connect a pose subscriber that never reads");
  CLI11_PARSE(app, argc, argv);

  spdlog::set_level(spdlog::level::warn);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  DaemonConfig config;
  config.sources = {"replay:" + replay};
  config.loop = true;
  config.replay_speed = speed;
  config.method = method;
  config.model_path = model;
  config.pub_endpoint = fmt::format("ipc:///tmp/bodyd-bench-{}/pose", ::getpid());
  config.control_endpoint = "none";
  config.outputs = outputs;
  std::vector<int> sink_fds;
  for (int port : udp_sinks) {
    const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<std::uint16_t>(port));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (fd < 0 || ::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
      fmt::print(stderr, "bodyd-bench-latency: --udp-sink {}: cannot bind 127.0.0.1:{} (in use?)\n", port, port);
      return 2;
    }
    sink_fds.push_back(fd);
  }
  if (std::string e = validate_config(config); !e.empty()) {
    fmt::print(stderr, "bodyd-bench-latency: {}\n", e);
    return 2;
  }
  std::string warning;
  const ModelChoice choice = choose_model(config, warning);
  if (!warning.empty()) fmt::print(stderr, "bodyd-bench-latency: {}\n", warning);

  const std::size_t total = static_cast<std::size_t>(frames + warmup);
  std::vector<FrameTiming> timings;
  timings.reserve(total);
  std::atomic<bool> done{false};
  Daemon daemon(config, make_default_factory(skeleton.empty() ? bundled_skeleton_path() : std::filesystem::path(skeleton)));
  daemon.set_frame_observer([&](const FrameTiming& t) {
    if (timings.size() < total) timings.push_back(t);
    if (timings.size() == total) done.store(true);
  });
  if (std::string e = daemon.start(); !e.empty()) {
    fmt::print(stderr, "bodyd-bench-latency: {}\n", e);
    return 1;
  }
  // The stalled subscriber: its subscription reaches the daemon during the warm-up.
  void* zmq_context = stalled_subscriber ? zmq_ctx_new() : nullptr;
  void* stalled = zmq_context ? zmq_socket(zmq_context, ZMQ_SUB) : nullptr;
  if (stalled) {
    const int one = 1, no_linger = 0;
    zmq_setsockopt(stalled, ZMQ_RCVHWM, &one, sizeof one);
    zmq_setsockopt(stalled, ZMQ_LINGER, &no_linger, sizeof no_linger);
    zmq_setsockopt(stalled, ZMQ_SUBSCRIBE, "", 0);
    if (zmq_connect(stalled, daemon.pub_endpoint().c_str()) != 0) {
      fmt::print(stderr, "bodyd-bench-latency: --stalled-subscriber: cannot connect to {}: {}\n", daemon.pub_endpoint(),
                 zmq_strerror(zmq_errno()));
      return 1;
    }
  }
  const std::string method_name = daemon.status().value("method", std::string("?"));
  if (!json_out)
    fmt::print("bodyd-bench-latency: {} poses (+{} warm-up) from {} at {}x the recorded rate, method {}{}\n", frames,
               warmup, replay, speed, method_name, stalled ? ", a stalled subscriber" : "");
  const double cpu0 = cpu_seconds();
  const auto wall0 = std::chrono::steady_clock::now();
  while (!done.load() && !g_stop) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const double cpu_s = cpu_seconds() - cpu0;
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const nlohmann::json status = daemon.status();
  daemon.stop();
  if (stalled) {
    zmq_close(stalled);
    zmq_ctx_term(zmq_context);
  }

  std::vector<std::int64_t> total_ns, queue_ns, reconstruct_ns, send_ns, overhead_ns, all_ns, outputs_ns;
  std::size_t failed = 0;
  for (std::size_t i = std::min<std::size_t>(warmup, timings.size()); i < timings.size(); ++i) {
    const FrameTiming& t = timings[i];
    total_ns.push_back(t.published_ns - t.arrival_ns);
    queue_ns.push_back(t.reconstruct_start_ns - t.arrival_ns);
    reconstruct_ns.push_back(t.reconstruct_end_ns - t.reconstruct_start_ns);
    send_ns.push_back(t.published_ns - t.reconstruct_end_ns);
    overhead_ns.push_back(total_ns.back() - reconstruct_ns.back());
    all_ns.push_back(t.outputs_sent_ns - t.arrival_ns);
    outputs_ns.push_back(t.outputs_sent_ns - t.published_ns);
    failed += t.sent ? 0 : 1;
  }
  const double cpu_percent = wall_s > 0 ? 100.0 * cpu_s / wall_s : 0.0;
  const double head_rate_hz = wall_s > 0 ? static_cast<double>(timings.size()) / wall_s : 0.0;
  std::vector<std::pair<const char*, Percentiles>> rows = {{"arrival -> published", percentiles_us(total_ns)},
                                                          {"  queue wait", percentiles_us(queue_ns)},
                                                          {"  reconstruction", percentiles_us(reconstruct_ns)},
                                                          {"  encode + send", percentiles_us(send_ns)},
                                                          {"latency - reconstruction", percentiles_us(overhead_ns)}};
  if (!outputs.empty()) {
    rows.emplace_back("arrival -> all outputs", percentiles_us(all_ns));
    rows.emplace_back("  outputs after --pub", percentiles_us(outputs_ns));
  }
  if (json_out) {
    nlohmann::json j{{"method", method_name},  {"frames", total_ns.size()},  {"cpu_percent_of_one_core", cpu_percent},
                     {"wall_s", wall_s},        {"cpu_s", cpu_s},              {"pose_rate_hz", head_rate_hz},
                     {"sends_failed", failed},  {"samples_dropped", status.value("samples_dropped", 0)},
                     {"stalled_subscriber", stalled_subscriber}};
    if (!outputs.empty()) j["outputs"] = status["outputs"];
    for (const auto& [name, p] : rows)
      j["latency_us"][name] = {{"p50", p.p50}, {"p90", p.p90}, {"p99", p.p99}, {"max", p.max}, {"mean", p.mean}};
    fmt::print("{}\n", j.dump(2));
  } else {
    fmt::print("{:<26} {:>9} {:>9} {:>9} {:>9} {:>9}   (microseconds)\n", "", "p50", "p90", "p99", "max", "mean");
    for (const auto& [name, p] : rows)
      fmt::print("{:<26} {:>9.1f} {:>9.1f} {:>9.1f} {:>9.1f} {:>9.1f}\n", name, p.p50, p.p90, p.p99, p.max, p.mean);
    fmt::print("poses: {} measured at {:.1f} Hz; sends failed: {}; samples dropped: {}\n", total_ns.size(), head_rate_hz,
               failed, status.value("samples_dropped", 0));
    if (!outputs.empty())
      for (const auto& o : status["outputs"])
        fmt::print("output {}: {} sent, {} failed{}\n", o.value("name", ""), o.value("sent", 0), o.value("send_failed", 0),
                   o.value("last_error", "").empty() ? "" : " (" + o.value("last_error", "") + ")");
    fmt::print("CPU: {:.2f} s over {:.2f} s wall = {:.1f}% of one core (whole process: sources, reconstruction, ZeroMQ)\n",
               cpu_s, wall_s, cpu_percent);
  }
  for (int fd : sink_fds) ::close(fd);
  return 0;
}
