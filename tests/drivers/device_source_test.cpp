// The HID and USB drivers over fake transports fed by simulated devices: streaming,
// several roles on one device, misbehaving devices, hotplug, stalls, clocks, the Razer
// Hydra's mode switch, and the daemon-facing specs (BODYD_FAKE_DEVICES).
#include "bodyd/io/devices/device_list.h"
#include "bodyd/io/devices/fake_devices.h"
#include "bodyd/io/devices/hid_source.h"
#include "bodyd/io/open_source.h"
#include "bodyd/io/devices/usb_source.h"
#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

#include "bodyd/test/sinks.h"
#include "bodyd/test/wait.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <functional>
#include <map>
#include <mutex>
#include <thread>

namespace bodyd::drivers {
namespace {

using namespace std::chrono_literals;

using test::CollectingSink;
using test::eventually;


const TrackerTrajectory& walk() {
  static const TrackerTrajectory t(read_bvh(test::fixtures() / "walk_60.bvh"));
  return t;
}

std::shared_ptr<SimulatedDevice> device(SimulatedDeviceConfig c, bool plugged = true) {
  auto d = std::make_shared<SimulatedDevice>(walk(), std::move(c));
  if (plugged) d->plug(monotonic_ns());
  return d;
}

HidSourceOptions hid_options(DeviceId id = {0x1209, 0xB0D1}) {
  HidSourceOptions o;
  o.name = "hid:test";
  o.devices = {id};
  o.rescan_interval_ms = 50;
  return o;
}

// A simulated device sampling at `hz`, the rest at its defaults.
SimulatedDeviceConfig at_rate(double hz) {
  SimulatedDeviceConfig c;
  c.sim.rate_hz = hz;
  return c;
}

TEST(HidSource, StreamsEveryRoleOfOneDeviceStampedAtRead) {
  SimulatedDeviceConfig c = at_rate(100.0);
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(device(c));
  CollectingSink sink;
  auto source = make_hid_source(hid_options(), transport);
  const std::int64_t t_start = monotonic_ns();
  ASSERT_EQ(source->start(sink, 3), "");
  ASSERT_TRUE(eventually([&] { return sink.size() >= 120; }, 3000ms));
  EXPECT_TRUE(source->status().connected);
  source->stop();
  const std::int64_t t_stop = monotonic_ns();

  // Every received pose is one the simulator produced for that role (bit-exact up to the
  // report's 0.1 mm quantisation).
  const std::vector<TrackerSample> truth = simulate_trackers(walk(), c.sim);
  std::map<Role, int> per_role;
  std::map<Role, std::int64_t> last_t;
  for (const SourceSample& s : sink.samples()) {
    ++per_role[s.sample.role];
    EXPECT_EQ(s.source_index, 3);
    EXPECT_TRUE(s.has_device_time);
    EXPECT_GE(s.sample.t_ns, t_start);
    EXPECT_LE(s.arrival_ns, t_stop);
    EXPECT_LE(s.sample.t_ns, s.arrival_ns);
    EXPECT_GE(s.sample.t_ns, last_t[s.sample.role]);  // per role, host time never goes back
    last_t[s.sample.role] = s.sample.t_ns;
    ASSERT_TRUE(s.sample.valid);
    bool found = false;
    for (const TrackerSample& t : truth)
      if (t.role == s.sample.role && (t.position_m - s.sample.position_m).cwiseAbs().maxCoeff() <= 0.51e-4 &&
          t.rotation.angularDistance(s.sample.rotation) < 2e-4) {
        found = true;
        break;
      }
    EXPECT_TRUE(found) << "pose not from the simulator: " << s.sample.position_m.transpose();
  }
  EXPECT_EQ(per_role.size(), 3u);
  for (auto [role, n] : per_role) EXPECT_GE(n, 30) << role_name(role);
  const DeviceStats st = source->stats();
  EXPECT_EQ(st.decode_errors, 0u);
  EXPECT_EQ(st.lost_reports, 0u);
  EXPECT_EQ(st.connects, 1u);
  EXPECT_EQ(source->status().samples, sink.size());
}

TEST(HidSource, MisbehavingDeviceIsCountedAndSurvived) {
  SimulatedDeviceConfig c = at_rate(200.0);
  c.faults.short_report_probability = 0.1;
  c.faults.garbage_probability = 0.1;
  c.faults.drop_probability = 0.1;
  c.faults.seed = 7;
  auto d = device(c);
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(d);
  CollectingSink sink;
  auto source = make_hid_source(hid_options(), transport);
  ASSERT_EQ(source->start(sink, 0), "");
  ASSERT_TRUE(eventually([&] { return source->stats().decode_errors >= 20; }, 4000ms));
  source->stop();
  const SimulatedDevice::Counters sent = d->counters();
  const DeviceStats st = source->stats();
  // Every short or garbage report was rejected, every good one delivered.
  EXPECT_EQ(st.decode_errors, sent.short_reports + sent.garbage);
  EXPECT_EQ(sink.size(), sent.sent - sent.short_reports - sent.garbage);
  EXPECT_EQ(st.reports, sink.size());
  // Dropped reports are gaps in the sequence; so are rejected ones (their numbers never arrive).
  EXPECT_GE(st.lost_reports + 2, sent.dropped);
  EXPECT_LE(st.lost_reports, sent.dropped + sent.short_reports + sent.garbage);
  EXPECT_GT(sent.dropped, 0u);
  EXPECT_NE(source->status().last_error.find("rejected a report"), std::string::npos);
  EXPECT_EQ(st.disconnects, 0u);
}

TEST(HidSource, DeviceAppearsDisappearsAndReappears) {
  SimulatedDeviceConfig c;
  auto d = device(c, /*plugged=*/false);
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(d);
  CollectingSink sink;
  auto source = make_hid_source(hid_options(), transport);
  ASSERT_EQ(source->start(sink, 0), "");

  // Nothing plugged in: waiting, and saying so.
  ASSERT_TRUE(eventually([&] { return !source->status().last_error.empty(); }, 1000ms));
  EXPECT_FALSE(source->status().connected);
  EXPECT_NE(source->status().last_error.find("no HID device 1209:B0D1 found"), std::string::npos)
      << source->status().last_error;

  d->plug(monotonic_ns());
  ASSERT_TRUE(eventually([&] { return sink.size() >= 10; }, 2000ms));
  EXPECT_TRUE(source->status().connected);

  d->unplug();
  ASSERT_TRUE(eventually([&] { return !source->status().connected; }, 1000ms));
  EXPECT_NE(source->status().last_error.find("unplugged"), std::string::npos) << source->status().last_error;
  EXPECT_EQ(source->stats().disconnects, 1u);
  const std::size_t before = sink.size();

  d->plug(monotonic_ns());
  ASSERT_TRUE(eventually([&] { return sink.size() >= before + 10; }, 2000ms));
  EXPECT_TRUE(source->status().connected);
  EXPECT_EQ(source->stats().connects, 2u);
  source->stop();
}

TEST(HidSource, HandDropsOutAndReturns) {
  SimulatedDeviceConfig c = at_rate(120.0);
  c.sim.dropout_rate_hz = 3.0;
  c.sim.dropout_mean_ms = 150.0;
  c.sim.seed = 3;
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(device(c));
  CollectingSink sink;
  auto source = make_hid_source(hid_options(), transport);
  ASSERT_EQ(source->start(sink, 0), "");
  // Wait until some hand has been lost and then tracked again.
  auto lost_and_back = [&] {
    for (Role hand : {Role::LeftHand, Role::RightHand}) {
      bool lost = false;
      for (const SourceSample& s : sink.samples()) {
        if (s.sample.role != hand) continue;
        if (!s.sample.valid) lost = true;
        if (lost && s.sample.valid) return true;
      }
    }
    return false;
  };
  ASSERT_TRUE(eventually(lost_and_back, 4000ms));
  source->stop();
  for (const SourceSample& s : sink.samples())
    if (s.sample.role == Role::Head) {
      EXPECT_TRUE(s.sample.valid);  // the head is never lost
    }
}

TEST(HidSource, StallIsReportedAndStreamingResumes) {
  SimulatedDeviceConfig c;
  c.roles = {Role::Head};
  c.faults.stall_at_s = 0.2;
  c.faults.stall_s = 0.5;
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(device(c));
  HidSourceOptions o = hid_options();
  o.stall_timeout_ms = 200;
  CollectingSink sink;
  auto source = make_hid_source(o, transport);
  ASSERT_EQ(source->start(sink, 0), "");
  ASSERT_TRUE(eventually([&] { return source->stats().stalls == 1; }, 2000ms));
  EXPECT_NE(source->status().last_error.find("stalled"), std::string::npos);
  EXPECT_TRUE(source->status().connected);  // still plugged in
  const std::size_t before = sink.size();
  ASSERT_TRUE(eventually([&] { return sink.size() > before + 10; }, 2000ms));
  source->stop();
  // The gap in host time is the stall.
  std::int64_t max_gap = 0;
  const auto s = sink.samples();
  for (std::size_t i = 1; i < s.size(); ++i) max_gap = std::max(max_gap, s[i].sample.t_ns - s[i - 1].sample.t_ns);
  EXPECT_GT(max_gap, 400'000'000);
}

TEST(HidSource, DeviceClockWrapsDriftsAndJumpsWhileHostStampsStayMonotonic) {
  SimulatedDeviceConfig c;
  c.roles = {Role::Head};
  c.sim.rate_hz = 100.0;
  c.clock_start_us = 0xFFFFFFFFu - 150'000;  // wraps 0.15 s in
  c.faults.clock_drift_ppm = 20000;            // 2 % fast
  c.faults.clock_jump_at_s = 0.6;
  c.faults.clock_jump_s = -5.0;                // steps back 5 s
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(device(c));
  CollectingSink sink;
  auto source = make_hid_source(hid_options(), transport);
  ASSERT_EQ(source->start(sink, 0), "");
  ASSERT_TRUE(eventually([&] { return source->stats().clock_jumps >= 1 && sink.size() >= 70; }, 3000ms));
  source->stop();
  EXPECT_EQ(source->stats().clock_jumps, 1u);  // the wrap is not a jump
  const auto s = sink.samples();
  // Before the jump the unwrapped device clock runs 2 % faster than the host's.
  std::size_t jump = 1;
  while (jump < s.size() && s[jump].device_t_ns > s[jump - 1].device_t_ns) ++jump;
  ASSERT_GE(jump, 40u);
  // Least-squares slope of device time against host time (robust to a late read or two).
  double mean_h = 0, mean_d = 0;
  for (std::size_t i = 0; i < jump; ++i) {
    mean_h += static_cast<double>(s[i].sample.t_ns - s[0].sample.t_ns) / jump;
    mean_d += static_cast<double>(s[i].device_t_ns - s[0].device_t_ns) / jump;
  }
  double sxy = 0, sxx = 0;
  for (std::size_t i = 0; i < jump; ++i) {
    const double h = static_cast<double>(s[i].sample.t_ns - s[0].sample.t_ns) - mean_h;
    const double d = static_cast<double>(s[i].device_t_ns - s[0].device_t_ns) - mean_d;
    sxy += h * d;
    sxx += h * h;
  }
  EXPECT_NEAR(sxy / sxx, 1.02, 0.01);
  EXPECT_GT(s[jump - 1].device_t_ns, 4'294'967'295'000);  // past the 32-bit wrap
  for (std::size_t i = 1; i < s.size(); ++i) EXPECT_GE(s[i].sample.t_ns, s[i - 1].sample.t_ns);
}

TEST(HidSource, RazerHydraIsSwitchedToMotionModeAndGivesBothHands) {
  SimulatedDeviceConfig c;
  c.name = "Hydra";
  c.id = {kHydraVendorId, kHydraProductId};
  c.protocol = FakeProtocol::Hydra;
  c.sim.rate_hz = 60.0;
  auto d = device(c);
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(d);
  CollectingSink sink;
  auto source = make_hid_source(hid_options({kHydraVendorId, kHydraProductId}), transport);
  ASSERT_EQ(source->start(sink, 0), "");
  ASSERT_TRUE(eventually([&] { return sink.size() >= 20; }, 4000ms));
  EXPECT_TRUE(d->counters().motion_mode);
  EXPECT_EQ(d->counters().feature_reports, 1u);
  source->stop();
  EXPECT_FALSE(d->counters().motion_mode);  // back to gamepad mode on close
  std::map<Role, int> per_role;
  const std::vector<TrackerSample> truth = simulate_trackers(walk(), c.sim);
  for (const SourceSample& s : sink.samples()) {
    ++per_role[s.sample.role];
    EXPECT_FALSE(s.has_device_time);
    bool found = false;
    for (const TrackerSample& t : truth)
      if (t.role == s.sample.role && (t.position_m - s.sample.position_m).norm() < 1e-3 &&
          t.rotation.angularDistance(s.sample.rotation) < 1e-3)
        found = true;
    EXPECT_TRUE(found) << role_name(s.sample.role) << " " << s.sample.position_m.transpose();
  }
  EXPECT_EQ(per_role.count(Role::Head), 0u);
  EXPECT_EQ(per_role[Role::LeftHand], per_role[Role::RightHand]);
  EXPECT_EQ(source->stats().decode_errors, 0u);
}

TEST(HidSource, StopIsPrompt) {
  SimulatedDeviceConfig c;
  c.roles = {Role::Head};
  c.sim.rate_hz = 2.0;  // reads mostly time out
  auto transport = std::make_shared<FakeHidTransport>();
  transport->add(device(c));
  CollectingSink sink;
  auto source = make_hid_source(hid_options(), transport);
  ASSERT_EQ(source->start(sink, 0), "");
  ASSERT_TRUE(eventually([&] { return source->status().connected; }, 1000ms));
  // stop() returns while the read waits for the next report, and nothing comes after it (how
  // long stopping takes: bodyd-bench-stop --hid-clip).
  EXPECT_TRUE(test::returns_within([&] { source->stop(); }, 10s));
  const std::size_t after_stop = sink.size();
  source->stop();  // idempotent
  std::this_thread::sleep_for(600ms);  // more than a report period at 2 Hz
  EXPECT_EQ(sink.size(), after_stop);
  EXPECT_FALSE(source->status().connected);
}

class UsbSourceTest : public ::testing::TestWithParam<bool> {};

TEST_P(UsbSourceTest, StreamsPackedTransfersAndSurvivesADisconnect) {
  const bool hotplug = GetParam();
  SimulatedDeviceConfig c = at_rate(100.0);
  c.faults.disconnect_at_s = 0.3;
  c.faults.reconnect_after_s = 0.3;
  auto transport = std::make_shared<FakeUsbTransport>(hotplug);
  transport->add(device(c));
  UsbSourceOptions o;
  o.name = "usb:test";
  o.devices = {{0x1209, 0xB0D1}};
  o.rescan_interval_ms = 100;
  CollectingSink sink;
  auto source = make_usb_source(o, transport);
  ASSERT_EQ(source->start(sink, 1), "");
  ASSERT_TRUE(eventually([&] { return source->stats().connects == 2 && sink.size() >= 150; }, 4000ms))
      << source->stats().connects << " " << sink.size();
  source->stop();
  const DeviceStats st = source->stats();
  EXPECT_EQ(st.disconnects, 1u);
  EXPECT_EQ(st.decode_errors, 0u);
  // Reports sent at the same moment travel in one transfer and share its stamp.
  const auto s = sink.samples();
  std::size_t shared_stamps = 0;
  std::int64_t max_gap = 0;
  for (std::size_t i = 1; i < s.size(); ++i) {
    shared_stamps += s[i].sample.t_ns == s[i - 1].sample.t_ns;
    max_gap = std::max(max_gap, s[i].sample.t_ns - s[i - 1].sample.t_ns);
  }
  EXPECT_GT(shared_stamps, 20u);
  EXPECT_GT(max_gap, 250'000'000);  // the time it was unplugged
}

INSTANTIATE_TEST_SUITE_P(HotplugOrRescan, UsbSourceTest, ::testing::Bool());

TEST(DeviceSpecs, ParseIdLists) {
  std::string error;
  auto ids = parse_device_ids("1209:b0d1,1532:0300", error);
  ASSERT_TRUE(ids) << error;
  ASSERT_EQ(ids->size(), 2u);
  EXPECT_EQ((*ids)[0], (DeviceId{0x1209, 0xB0D1}));
  EXPECT_EQ((*ids)[1], (DeviceId{0x1532, 0x0300}));
  for (const char* bad : {"", "1209", "1209:", ":B0D1", "12345:1", "1209:xyz", "1209:B0D1,", "-1:2"}) {
    EXPECT_FALSE(parse_device_ids(bad, error)) << bad;
    EXPECT_NE(error.find("VID:PID"), std::string::npos);
  }
  EXPECT_EQ(open_source("hid:nope", SourceOptions{}, error), nullptr);
  EXPECT_NE(error.find("hid:nope"), std::string::npos) << error;
}

TEST(DeviceSpecs, SimulatedDevicesThroughTheDaemonSpecs) {
  ::setenv("BODYD_FAKE_DEVICES", (test::fixtures() / "walk_60.bvh").c_str(), 1);
  const std::string listing = list_devices_text();
  for (const char* spec : {"hid:1209:B0D1", "hid:1209:B0D2", "hid:1532:0300", "usb:1209:B0D1"})
    EXPECT_NE(listing.find(spec), std::string::npos) << spec << " missing from:\n" << listing;

  std::string error;
  auto head = open_source("hid:1209:B0D2", SourceOptions{}, error);
  ASSERT_TRUE(head) << error;
  auto usb = open_source("usb:1209:B0D1", SourceOptions{}, error);
  ASSERT_TRUE(usb) << error;
  CollectingSink sink;
  ASSERT_EQ(head->start(sink, 0), "");
  ASSERT_EQ(usb->start(sink, 1), "");
  ASSERT_TRUE(eventually(
      [&] {
        std::map<int, int> by_source;
        for (const auto& s : sink.samples()) ++by_source[s.source_index];
        return by_source[0] >= 10 && by_source[1] >= 30;
      },
      3000ms));
  head->stop();
  usb->stop();
  for (const auto& s : sink.samples())
    if (s.source_index == 0) {
      EXPECT_EQ(s.sample.role, Role::Head);
    }
  EXPECT_EQ(head->status().name, "hid:1209:B0D2");
}

TEST(DeviceList, NothingFoundIsAnEmptyList) {
  FakeHidTransport hid;
  FakeUsbTransport usb;
  EXPECT_TRUE(list_devices(&hid, &usb).empty());
  EXPECT_TRUE(list_devices(nullptr, nullptr).empty());
  // Trackers that are not plugged in and a USB device bodyd does not know are not found either...
  auto hid_tracker = device({}, false);
  auto usb_tracker = device({}, false);
  SimulatedDeviceConfig mouse;
  mouse.id = {0x046d, 0xc52b};
  usb.add(device(mouse));
  hid.add(hid_tracker);
  usb.add(usb_tracker);
  EXPECT_TRUE(list_devices(&hid, &usb).empty());
  // ...while the same transports list the trackers, once each, when they are plugged in.
  hid_tracker->plug(monotonic_ns());
  usb_tracker->plug(monotonic_ns());
  const std::vector<ListedDevice> listed = list_devices(&hid, &usb);
  ASSERT_EQ(listed.size(), 2u);
  EXPECT_EQ(listed[0].spec, "hid:1209:B0D1");
  EXPECT_EQ(listed[1].spec, "usb:1209:B0D1");
}

// Issue 20 item 8: with nothing found, the text names the network inputs a headset user needs
// and the bundled recording to try, by the path given, and advertises no input that does not exist.
TEST(DeviceList, NothingFoundNamesTheNetworkInputsAndTheBundledRecording) {
  const std::string text = no_tracker_device_text("/usr/share/bodyd/data/demo/walk.csv");
  for (const char* part : {"no tracker device found", "docs/drivers.md", "bodyd --source vrchat:", "bodyd --source vmc:",
                           "docs/vr-apps.md", "bodyd --source replay:/usr/share/bodyd/data/demo/walk.csv"})
    EXPECT_NE(text.find(part), std::string::npos) << "missing \"" << part << "\" in:\n" << text;
  for (const char* absent : {"steamvr", "monado"}) EXPECT_EQ(text.find(absent), std::string::npos) << text;
  // Every input it names is one open_source knows (a port of 0 so nothing stays bound).
  std::string error;
  for (const char* spec : {"vrchat:127.0.0.1:0?oscquery=off", "vmc:127.0.0.1:0"})
    EXPECT_NE(open_source(spec, SourceOptions{}, error), nullptr) << spec << ": " << error;
  const std::string unknown = no_tracker_device_text("");
  EXPECT_NE(unknown.find("no --source plays the bundled recording"), std::string::npos) << unknown;
}

}  // namespace
}  // namespace bodyd::drivers
