// Timing: two simulated devices at different rates, with jittered sample times and
// drifting device clocks, read by the real HID driver threads; the samples carry host
// monotonic stamps taken at read. The reconstructor (the ik baseline; also the diffusion
// model when models/bodyd-default.safetensors exists) must give the same output whatever
// the interleaving of roles in which the same samples reach it.
#include "bodyd/io/devices/fake_devices.h"
#include "bodyd/io/devices/hid_source.h"
#include "bodyd/inference/factory.h"
#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <mutex>
#include <random>
#include <thread>

namespace bodyd::drivers {
namespace {

class VectorSink final : public SampleSink {
 public:
  void push(const SourceSample& s) override {
    std::lock_guard lock(mutex);
    samples.push_back(s.sample);
  }
  bool push_wait(const SourceSample& s, std::chrono::nanoseconds) override {
    push(s);
    return true;
  }
  std::mutex mutex;
  std::vector<TrackerSample> samples;  // in arrival order
};

// Reconstructs at `queries`, pushing before each query every sample with t_ns <= query,
// in the order `order` gives (a permutation of `samples`). Returns the joint positions.
std::vector<std::vector<Vec3>> run(Reconstructor& recon, const std::vector<TrackerSample>& samples,
                                   const std::vector<std::int64_t>& queries, const std::vector<std::size_t>& order) {
  recon.reset();
  std::vector<std::vector<Vec3>> out;
  std::vector<bool> pushed(samples.size(), false);
  for (const std::int64_t q : queries) {
    for (const std::size_t i : order)
      if (!pushed[i] && samples[i].t_ns <= q) {
        recon.push(samples[i]);
        pushed[i] = true;
      }
    BodyPose pose;
    if (recon.reconstruct(q, pose)) out.push_back(pose.global.positions);
  }
  return out;
}

TEST(Timing, ReconstructionDoesNotDependOnTheInterleavingOfRoles) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const TrackerTrajectory trajectory(clip);
  SimulatedDeviceConfig head;
  head.name = "headset";
  head.roles = {Role::Head};
  head.sim.rate_hz = 90.0;
  head.sim.jitter_ms = 2.0;
  head.faults.clock_drift_ppm = 300;
  SimulatedDeviceConfig hands;
  hands.name = "hands";
  hands.id = {0x1209, 0xB0D2};
  hands.roles = {Role::LeftHand, Role::RightHand};
  hands.sim.role_rate_hz = {0.0, 72.0, 55.0};
  hands.sim.jitter_ms = 3.0;
  hands.sim.seed = 9;
  hands.faults.clock_drift_ppm = -450;
  auto transport = std::make_shared<FakeHidTransport>();
  for (const auto& c : {head, hands}) {
    auto d = std::make_shared<SimulatedDevice>(trajectory, c);
    d->plug(monotonic_ns());
    transport->add(d);
  }
  HidSourceOptions o;
  o.name = "hid:timing";
  o.devices = {{0x1209, 0xB0D1}, {0x1209, 0xB0D2}};
  o.rescan_interval_ms = 20;
  auto source = make_hid_source(o, transport);
  VectorSink sink;
  ASSERT_EQ(source->start(sink, 0), "");
  std::this_thread::sleep_for(std::chrono::milliseconds(900));
  source->stop();
  const std::vector<TrackerSample> samples = sink.samples;
  ASSERT_GT(samples.size(), 100u);

  // Host stamps: per role never decreasing; the roles arrive interleaved by the threads.
  std::array<std::int64_t, kRoleCount> last{};
  std::array<int, kRoleCount> count{};
  for (const TrackerSample& s : samples) {
    const auto r = static_cast<std::size_t>(s.role);
    EXPECT_GE(s.t_ns, last[r]);
    last[r] = s.t_ns;
    ++count[r];
  }
  for (Role r : kXrRoles) EXPECT_GT(count[static_cast<std::size_t>(r)], 20);  // the devices: headset and hands

  // Orders: arrival; sorted by time; roles in blocks (right, left, head); a random
  // interleaving that keeps each role's own order (what any set of threads could produce).
  const std::size_t n = samples.size();
  std::vector<std::size_t> arrival(n);
  for (std::size_t i = 0; i < n; ++i) arrival[i] = i;
  std::vector<std::size_t> by_time = arrival;
  std::stable_sort(by_time.begin(), by_time.end(),
                   [&](std::size_t a, std::size_t b) { return samples[a].t_ns < samples[b].t_ns; });
  std::vector<std::size_t> blocks = arrival;
  std::stable_sort(blocks.begin(), blocks.end(), [&](std::size_t a, std::size_t b) {
    return static_cast<int>(samples[a].role) > static_cast<int>(samples[b].role);
  });
  std::vector<std::size_t> shuffled;
  {
    std::mt19937 rng(5);
    std::array<std::vector<std::size_t>, kRoleCount> queues;
    for (std::size_t i : arrival) queues[static_cast<std::size_t>(samples[i].role)].push_back(i);
    std::array<std::size_t, kRoleCount> next{};
    while (shuffled.size() < n) {
      const std::size_t r = rng() % kXrRoleCount;  // the devices' roles: headset and hands
      if (next[r] < queues[r].size()) shuffled.push_back(queues[r][next[r]++]);
    }
  }

  std::vector<std::int64_t> queries;
  const std::int64_t last_of_all = *std::min_element(last.begin(), last.begin() + kXrRoleCount);
  const std::int64_t t0 = last_of_all - 600'000'000;
  for (std::int64_t q = t0; q < last_of_all; q += 33'333'333) queries.push_back(q);

  const Motion skeleton_clip = read_bvh(test::source_dir() / "data" / "demo" / "skeleton.bvh");
  std::vector<std::pair<std::string, std::filesystem::path>> methods{{"ik", ""}};
  const auto model = test::source_dir() / "models" / "bodyd-default.safetensors";
  if (std::filesystem::exists(model)) methods.emplace_back("diffusion", model);
  for (const auto& [method, path] : methods) {
    SCOPED_TRACE(method);
    std::unique_ptr<Reconstructor> recon = make_reconstructor(method, path, &skeleton_clip.skeleton);
    const auto reference = run(*recon, samples, queries, arrival);
    ASSERT_GE(reference.size(), 10u);
    for (const auto* order : {&by_time, &blocks, &shuffled}) {
      const auto other = run(*recon, samples, queries, *order);
      ASSERT_EQ(other.size(), reference.size());
      for (std::size_t f = 0; f < other.size(); ++f)
        for (std::size_t j = 0; j < other[f].size(); ++j)
          ASSERT_LT((other[f][j] - reference[f][j]).norm(), 1e-9) << "frame " << f << " joint " << j;
    }
  }
}

}  // namespace
}  // namespace bodyd::drivers
