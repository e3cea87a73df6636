// bodyd-bench-stop: how long stopping a tracker source takes, and how late a paced replay
// delivers (docs/drivers.md, "Benchmark"). The tests check that a source stops and what it
// delivers; how fast is measured here, because it depends on the machine and its load.
//
//   bodyd-bench-stop [--runs 20] [--json] [--hid-clip tests/data/walk_60.bvh]
//
// Cases (each run starts a fresh source and times stop() from the call to its return):
//   replay, blocked on a full sink     a looped, unpaced replay waiting for room (target < 500 ms)
//   replay, waiting for a far sample   a paced replay whose next sample is a minute away (< 500 ms)
//   udp: source                        the UDP input idle (< 1000 ms)
//   vrchat: with an OSCQuery client    OSCQuery's HTTP server with a client connected (< 1000 ms)
//   hid: waiting for a report          (with --hid-clip) a simulated 2 Hz HID tracker (< 200 ms)
// and, for a paced replay of 20 samples at 200 Hz, the largest delay of a sample's arrival
// after its due time (target < 50 ms) and the whole replay's length (95 ms of log; < 1000 ms);
// with --hid-clip, for a simulated 100 Hz HID tracker, the largest time from a report's read
// (the sample's stamp) to its push into the sink (target < 50 ms).
#include "bodyd/base/user_error.h"
#include "bodyd/io/devices/fake_devices.h"
#include "bodyd/io/devices/hid_source.h"
#include "bodyd/io/osc/network_source.h"
#include "bodyd/io/open_source.h"
#include "bodyd/io/replay/replay_source.h"
#include "bodyd/motion/bvh.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace bodyd;
using namespace bodyd::drivers;
using namespace std::chrono_literals;

// A sink that is always full: push_wait waits its whole timeout and refuses.
class FullSink final : public SampleSink {
 public:
  void push(const SourceSample&) override {}
  bool push_wait(const SourceSample&, std::chrono::nanoseconds timeout) override {
    std::this_thread::sleep_for(timeout);
    return false;
  }
};

// Keeps every sample.
class KeepingSink final : public SampleSink {
 public:
  void push(const SourceSample& s) override {
    std::lock_guard lock(mutex_);
    samples_.push_back(s);
  }
  bool push_wait(const SourceSample& s, std::chrono::nanoseconds) override {
    push(s);
    return true;
  }
  std::vector<SourceSample> samples() const {
    std::lock_guard lock(mutex_);
    return samples_;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<SourceSample> samples_;
};

// `n` head samples `period_ns` apart.
std::vector<TrackerSample> head_samples(int n, std::int64_t period_ns) {
  std::vector<TrackerSample> out;
  for (int i = 0; i < n; ++i) {
    TrackerSample s;
    s.t_ns = 1'000'000'000 + i * period_ns;
    s.role = Role::Head;
    s.valid = true;
    s.position_m = Vec3(0, 1.6, 0);
    out.push_back(s);
  }
  return out;
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Milliseconds `source->stop()` took, after `ready` (the source is in the state to measure).
double time_stop(TrackerSource& source, const std::function<void()>& ready) {
  ready();
  const auto t0 = std::chrono::steady_clock::now();
  source.stop();
  return ms_since(t0);
}

struct Case {
  std::string name;
  double target_ms;
  std::vector<double> ms;
};

std::unique_ptr<TrackerSource> must_open(const std::string& spec) {
  std::string error;
  auto source = open_source(spec, SourceOptions{}, error);
  if (!source) throw UserError(spec, error);
  return source;
}

// Starts `source` into `sink`; a source that cannot start (a busy port, say) says why.
void must_start(TrackerSource& source, SampleSink& sink) {
  if (std::string e = source.start(sink, 0); !e.empty()) throw UserError("", e);
}

int connect_to(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// A started HID source reading one simulated head tracker of `rate_hz` through the fake transport.
std::unique_ptr<TrackerSource> start_simulated_hid(const TrackerTrajectory& trajectory, double rate_hz, SampleSink& sink) {
  SimulatedDeviceConfig c;
  c.roles = {Role::Head};
  c.sim.rate_hz = rate_hz;
  auto device = std::make_shared<SimulatedDevice>(trajectory, c);
  device->plug(monotonic_ns());
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(device);
  HidSourceOptions o;
  o.name = "hid:bench";
  o.devices = {c.id};
  o.rescan_interval_ms = 50;
  auto source = make_hid_source(o, transport);
  must_start(*source, sink);
  return source;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bodyd-bench-stop: how long stopping a tracker source takes (docs/drivers.md)"};
  int runs = 20;
  bool json = false;
  std::string hid_clip;
  app.add_option("--runs", runs, "runs per case")->check(CLI::Range(1, 10000));
  app.add_option("--hid-clip", hid_clip, "a BVH clip for a simulated HID tracker (also time its stop)")
      ->check(CLI::ExistingFile);
  app.add_flag("--json", json, "one JSON object");
  CLI11_PARSE(app, argc, argv);
  spdlog::set_level(spdlog::level::err);  // the sources' open/close lines are not the output

  std::vector<Case> cases = {{"replay, blocked on a full sink", 500, {}},
                             {"replay, waiting for a far sample", 500, {}},
                             {"udp: source", 1000, {}},
                             {"vrchat: with an OSCQuery client", 1000, {}}};
  std::unique_ptr<TrackerTrajectory> trajectory;
  if (!hid_clip.empty()) {
    cases.push_back({"hid: waiting for a report", 200, {}});
    try {
      trajectory = std::make_unique<TrackerTrajectory>(read_bvh(hid_clip));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bodyd-bench-stop: %s: %s\n", hid_clip.c_str(), e.what());
      return 1;
    }
  }
  double worst_late_ms = 0, worst_replay_ms = 0, worst_hid_push_ms = 0;
  try {
    for (int r = 0; r < runs; ++r) {
      {
        ReplayOptions o;
        o.paced = false;
        o.loop = true;
        FullSink full;
        auto source = make_replay_source("bench", head_samples(10, 11'000'000), o);
        must_start(*source, full);
        cases[0].ms.push_back(time_stop(*source, [] { std::this_thread::sleep_for(20ms); }));
      }
      {
        std::vector<TrackerSample> far = head_samples(2, 60'000'000'000);  // a minute apart
        KeepingSink sink;
        auto source = make_replay_source("bench", far, ReplayOptions{});
        must_start(*source, sink);
        cases[1].ms.push_back(time_stop(*source, [] { std::this_thread::sleep_for(20ms); }));
      }
      {
        KeepingSink sink;
        auto source = must_open("udp:127.0.0.1:0");
        must_start(*source, sink);
        cases[2].ms.push_back(time_stop(*source, [] { std::this_thread::sleep_for(10ms); }));
      }
      {
        KeepingSink sink;
        auto source = must_open("vrchat:127.0.0.1:0");
        must_start(*source, sink);
        auto* network = dynamic_cast<NetworkSource*>(source.get());
        const int port = network ? network->oscquery_port() : 0;
        const int fd = port > 0 ? connect_to(port) : -1;
        cases[3].ms.push_back(time_stop(*source, [] { std::this_thread::sleep_for(10ms); }));
        if (fd >= 0) ::close(fd);
      }
      if (trajectory) {
        KeepingSink sink;
        auto source = start_simulated_hid(*trajectory, 2.0, sink);  // reads mostly wait
        const std::int64_t start = monotonic_ns();
        while (!source->status().connected && monotonic_ns() - start < 5'000'000'000) std::this_thread::sleep_for(5ms);
        cases[4].ms.push_back(time_stop(*source, [] { std::this_thread::sleep_for(10ms); }));
      }
      if (trajectory) {
        KeepingSink sink;
        auto source = start_simulated_hid(*trajectory, 100.0, sink);
        const std::int64_t start = monotonic_ns();
        while (sink.samples().size() < 30 && monotonic_ns() - start < 10'000'000'000) std::this_thread::sleep_for(5ms);
        source->stop();
        const std::vector<SourceSample> got = sink.samples();
        if (got.empty())
          throw UserError("hid:bench", "the simulated HID tracker sent nothing in 10 s",
                          "run it again on a less loaded machine; if it persists, report it");
        for (const SourceSample& s : got)
          worst_hid_push_ms = std::max(worst_hid_push_ms, (s.arrival_ns - s.sample.t_ns) * 1e-6);
      }
      {
        const std::vector<TrackerSample> samples = head_samples(20, 5'000'000);  // 200 Hz, 95 ms
        KeepingSink sink;
        auto source = make_replay_source("bench", samples, ReplayOptions{});
        const std::int64_t start = monotonic_ns();
        must_start(*source, sink);
        while (sink.samples().size() < samples.size() && monotonic_ns() - start < 10'000'000'000)
          std::this_thread::sleep_for(1ms);
        source->stop();
        const std::vector<SourceSample> got = sink.samples();
        if (got.size() != samples.size())
          throw UserError(
              "replay", fmt::format("the paced replay delivered {} of {} samples in 10 s", got.size(), samples.size()),
              "run it again on a less loaded machine; if it persists, report it");
        for (std::size_t i = 0; i < got.size(); ++i) {
          const std::int64_t due = got[0].arrival_ns + (samples[i].t_ns - samples[0].t_ns);
          worst_late_ms = std::max(worst_late_ms, (got[i].arrival_ns - due) * 1e-6);
        }
        worst_replay_ms = std::max(worst_replay_ms, (got.back().arrival_ns - start) * 1e-6);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bodyd-bench-stop: %s\n", e.what());
    return 1;
  }

  bool all_met = worst_late_ms < 50 && worst_replay_ms < 1000 && worst_hid_push_ms < 50;
  std::string out = json ? "{\"runs\": " + std::to_string(runs) + ", \"stop_ms\": {" : "";
  if (!json) out += fmt::format("{} runs per case (milliseconds)\n{:<36} {:>8} {:>8} {:>8}\n", runs, "stop()", "median",
                                "max", "target");
  for (std::size_t i = 0; i < cases.size(); ++i) {
    std::vector<double> ms = cases[i].ms;
    std::sort(ms.begin(), ms.end());
    const double median = ms[ms.size() / 2], max = ms.back();
    all_met = all_met && max < cases[i].target_ms;
    if (json)
      out += fmt::format("{}\"{}\": {{\"median\": {:.3f}, \"max\": {:.3f}, \"target\": {}}}", i ? ", " : "",
                         cases[i].name, median, max, cases[i].target_ms);
    else
      out += fmt::format("{:<36} {:>8.2f} {:>8.2f} {:>8.0f}\n", cases[i].name, median, max, cases[i].target_ms);
  }
  if (json) {
    out += fmt::format("}}, \"paced_replay\": {{\"max_late_ms\": {:.3f}, \"max_total_ms\": {:.3f}}}", worst_late_ms,
                       worst_replay_ms);
    if (trajectory) out += fmt::format(", \"hid_read_to_push_max_ms\": {:.3f}", worst_hid_push_ms);
    out += fmt::format(", \"targets_met\": {}}}\n", all_met ? "true" : "false");
  } else {
    out += fmt::format("paced replay, 20 samples at 200 Hz: latest arrival after due {:.2f} ms (target 50), "
                       "whole replay {:.2f} ms (target 1000)\n",
                       worst_late_ms, worst_replay_ms);
    if (trajectory)
      out += fmt::format("hid: 100 Hz tracker, latest push after its read {:.3f} ms (target 50)\n", worst_hid_push_ms);
    out += fmt::format("targets {}\n", all_met ? "met" : "MISSED");
  }
  std::fputs(out.c_str(), stdout);
  return 0;
}
