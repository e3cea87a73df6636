#include "bodyd/io/devices/fake_devices.h"

#include "device_protocol.h"

#include "bodyd/base/random.h"
#include "bodyd/io/devices/report.h"
#include "bodyd/motion/bvh.h"

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <thread>

namespace bodyd::drivers {
namespace {

constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();

// splitmix64 (bodyd/base/random.h): a tiny, seedable generator with the same output everywhere.
double uniform01(std::uint64_t& state) { return static_cast<double>(splitmix64(state) >> 11) * 0x1.0p-53; }

void sleep_until_ns(std::int64_t t_ns) {
  std::this_thread::sleep_until(std::chrono::steady_clock::time_point(std::chrono::nanoseconds(t_ns)));
}

}  // namespace

// ---------------------------------------------------------------------------------------
SimulatedDevice::SimulatedDevice(const TrackerTrajectory& trajectory, SimulatedDeviceConfig config)
    : config_(std::move(config)), rng_state_(config_.faults.seed) {
  const std::vector<TrackerSample> samples = simulate_trackers(trajectory, config_.sim);
  if (config_.protocol == FakeProtocol::Hydra) {
    // One report carries both controllers: pair the k-th samples of the two roles.
    std::array<std::vector<TrackerSample>, 2> by_controller;
    for (const TrackerSample& s : samples)
      for (int c = 0; c < 2; ++c)
        if (s.role == config_.hydra.controller_roles[c]) by_controller[c].push_back(s);
    const std::size_t n = std::min(by_controller[0].size(), by_controller[1].size());
    for (std::size_t k = 0; k < n; ++k)
      items_.push_back({by_controller[0][k].t_ns, {by_controller[0][k], by_controller[1][k]}});
  } else {
    for (const TrackerSample& s : samples)
      if (std::find(config_.roles.begin(), config_.roles.end(), s.role) != config_.roles.end())
        items_.push_back({s.t_ns, {s}});
  }
  std::stable_sort(items_.begin(), items_.end(), [](const Item& a, const Item& b) { return a.t_ns < b.t_ns; });
  double max_rate_hz = config_.sim.rate_hz;
  for (const Role r : kRoles) max_rate_hz = std::max(max_rate_hz, config_.sim.rate_of(r));
  if (!items_.empty())
    loop_span_ns_ = items_.back().t_ns - items_.front().t_ns + static_cast<std::int64_t>(1e9 / max_rate_hz);
}

void SimulatedDevice::plug(std::int64_t now_ns) {
  std::lock_guard lock(mutex_);
  plugged_ = true;
  plug_ns_ = now_ns;
  ++generation_;
  next_ = 0;
  loop_ = 0;
}

void SimulatedDevice::unplug() {
  std::lock_guard lock(mutex_);
  plugged_ = false;
}

bool SimulatedDevice::in_window(std::int64_t t_ns, double at_s, double length_s) const {
  if (at_s < 0.0) return false;
  const auto start_ns = static_cast<std::int64_t>(at_s * 1e9);
  if (t_ns < start_ns) return false;
  return length_s < 0.0 || t_ns < start_ns + static_cast<std::int64_t>(length_s * 1e9);
}

bool SimulatedDevice::present(std::int64_t now_ns, std::uint64_t* out_generation) const {
  std::lock_guard lock(mutex_);
  const DeviceFaults& f = config_.faults;
  const std::int64_t t = now_ns - plug_ns_;
  if (out_generation) {
    // A scheduled reconnection is a new plug-in: handles opened before it are stale.
    const bool reconnected = f.disconnect_at_s >= 0.0 && f.reconnect_after_s >= 0.0 &&
                             t >= static_cast<std::int64_t>((f.disconnect_at_s + f.reconnect_after_s) * 1e9);
    *out_generation = generation_ * 2 + (reconnected ? 1 : 0);
  }
  return plugged_ && !in_window(t, f.disconnect_at_s, f.reconnect_after_s);
}

std::int64_t SimulatedDevice::due_ns(std::size_t index, std::int64_t loop) const {
  return plug_ns_ + loop * loop_span_ns_ + (items_[index].t_ns - items_.front().t_ns);
}

std::optional<std::vector<std::uint8_t>> SimulatedDevice::poll(std::int64_t now_ns, std::int64_t& out_next_due_ns) {
  std::lock_guard lock(mutex_);
  out_next_due_ns = kNever;
  if (!plugged_ || items_.empty()) return std::nullopt;
  const DeviceFaults& f = config_.faults;
  for (;;) {
    if (next_ >= items_.size()) {
      if (!config_.loop) return std::nullopt;
      next_ = 0;
      ++loop_;
    }
    const std::int64_t due = due_ns(next_, loop_);
    if (due > now_ns) {
      out_next_due_ns = due;
      return std::nullopt;
    }
    const Item& item = items_[next_++];
    const std::int64_t t_rel = due - plug_ns_;
    // Unplugged or stalled: nothing is sent (and nothing numbered).
    if (in_window(t_rel, f.disconnect_at_s, f.reconnect_after_s) || in_window(t_rel, f.stall_at_s, f.stall_s))
      continue;
    if (config_.protocol == FakeProtocol::Hydra && config_.hydra_starts_in_gamepad_mode && !counters_.motion_mode)
      continue;
    const std::vector<std::uint8_t> clean = encode(item, t_rel);
    ++sequence_;
    if (f.drop_probability > 0.0 && uniform01(rng_state_) < f.drop_probability) {
      ++counters_.dropped;
      continue;
    }
    std::vector<std::uint8_t> bytes = clean;
    if (f.garbage_probability > 0.0 && uniform01(rng_state_) < f.garbage_probability) {
      bytes.resize(1 + splitmix64(rng_state_) % 64);
      for (auto& b : bytes) b = static_cast<std::uint8_t>(splitmix64(rng_state_));
      ++counters_.garbage;
    } else if (f.short_report_probability > 0.0 && uniform01(rng_state_) < f.short_report_probability) {
      bytes.resize(splitmix64(rng_state_) % bytes.size());  // 0 .. size-1 bytes
      ++counters_.short_reports;
    }
    ++counters_.sent;
    return bytes;
  }
}

std::vector<std::uint8_t> SimulatedDevice::encode(const Item& item, std::int64_t t_rel_ns) {
  return detail::device_protocol_row(config_.protocol).encode_fake({config_, item.samples, sequence_, t_rel_ns});
}

namespace detail {

// The Hydra's fake encoder (device_protocol.h): both controllers in one report.
std::vector<std::uint8_t> encode_hydra_fake(const FakeReport& report) {
  HydraReport r;
  r.sequence = static_cast<std::uint8_t>(report.sequence);
  for (int c = 0; c < 2; ++c) {
    const TrackerSample& s = report.samples[static_cast<std::size_t>(c)];
    r.controllers[c].valid = s.valid;
    r.controllers[c].position_m = s.position_m;
    r.controllers[c].rotation = s.rotation;
  }
  const auto bytes = encode_hydra_report(r, report.config.hydra);
  return {bytes.begin(), bytes.end()};
}

// The bodyd report's fake encoder (device_protocol.h): one role per report, with the device
// clock (drift and jump faults applied).
std::vector<std::uint8_t> encode_bodyd_report_fake(const FakeReport& report) {
  const DeviceFaults& f = report.config.faults;
  const std::int64_t t_rel_ns = report.t_rel_ns;
  double device_us = static_cast<double>(t_rel_ns) * 1e-3 * (1.0 + f.clock_drift_ppm * 1e-6);
  if (f.clock_jump_at_s >= 0.0 && t_rel_ns >= static_cast<std::int64_t>(f.clock_jump_at_s * 1e9))
    device_us += f.clock_jump_s * 1e6;
  const auto clock = static_cast<std::int64_t>(report.config.clock_start_us) + static_cast<std::int64_t>(device_us);
  const TrackerSample& s = report.samples.front();
  TrackerReport r;
  r.role = s.role;
  r.valid = s.valid;
  r.sequence = report.sequence;
  r.battery_percent = 80;
  r.device_time_us = static_cast<std::uint32_t>(static_cast<std::uint64_t>(clock));  // wraps like a device's
  r.position_m = s.position_m;
  r.rotation = s.rotation;
  std::array<std::uint8_t, kTrackerReportSize> bytes{};
  if (encode_tracker_report(r, bytes) != ReportError::None) {
    r.valid = false;  // not representable (far outside the range a tracker reports): tracking lost
    (void)encode_tracker_report(r, bytes);
  }
  return {bytes.begin(), bytes.end()};
}

}  // namespace detail

void SimulatedDevice::feature_report(const std::uint8_t* data, std::size_t size) {
  std::lock_guard lock(mutex_);
  ++counters_.feature_reports;
  const auto motion = hydra_motion_mode_feature_report();
  const auto gamepad = hydra_gamepad_mode_feature_report();
  if (size == motion.size() && std::equal(motion.begin(), motion.end(), data)) counters_.motion_mode = true;
  if (size == gamepad.size() && std::equal(gamepad.begin(), gamepad.end(), data)) counters_.motion_mode = false;
}

SimulatedDevice::Counters SimulatedDevice::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

// ---------------------------------------------------------------------------------------
namespace {

// Reads one simulated device as a transport would: waits for the next due report, up to
// the timeout; fails once the device is unplugged (or was re-plugged since the open).
class FakeReader {
 public:
  FakeReader(std::shared_ptr<SimulatedDevice> device, std::uint64_t generation)
      : device_(std::move(device)), generation_(generation) {}

  // Data: `out` holds a report; Timeout; Gone.
  ReadStatus next(std::vector<std::uint8_t>& out, std::int64_t deadline_ns, bool silent) {
    for (;;) {
      const std::int64_t now = monotonic_ns();
      std::uint64_t generation = 0;
      if (!device_->present(now, &generation) || generation != generation_) return ReadStatus::Gone;
      std::int64_t next_due = kNever;
      if (!silent) {
        if (auto r = device_->poll(now, next_due)) {
          out = std::move(*r);
          return ReadStatus::Data;
        }
      }
      if (now >= deadline_ns) return ReadStatus::Timeout;
      // Wake at least every 10 ms to notice an unplug, as a read on a real device would fail.
      sleep_until_ns(std::min({next_due, deadline_ns, now + 10'000'000}));
    }
  }
  SimulatedDevice& device() { return *device_; }

 private:
  std::shared_ptr<SimulatedDevice> device_;
  std::uint64_t generation_;
};

std::string gone_text(const SimulatedDevice& d) { return "simulated device \"" + d.config().name + "\" unplugged"; }

class FakeHidHandle final : public HidDevice {
 public:
  FakeHidHandle(std::shared_ptr<SimulatedDevice> device, std::uint64_t generation, bool control)
      : reader_(std::move(device), generation), control_(control) {}

  ReadResult read(std::uint8_t* buffer, std::size_t capacity, int timeout_ms) override {
    ReadResult r;
    std::vector<std::uint8_t> bytes;
    r.status = reader_.next(bytes, monotonic_ns() + std::int64_t{timeout_ms} * 1'000'000, control_);
    if (r.status == ReadStatus::Gone) r.error = gone_text(reader_.device());
    if (r.status == ReadStatus::Data) {
      r.size = std::min(bytes.size(), capacity);  // hidraw truncates too
      std::copy_n(bytes.begin(), r.size, buffer);
    }
    return r;
  }
  std::string send_feature_report(const std::uint8_t* data, std::size_t size) override {
    reader_.device().feature_report(data, size);
    return {};
  }

 private:
  FakeReader reader_;
  bool control_;  // a Hydra's control interface streams nothing
};

// USB transfers pack every whole report already due (up to the buffer), like a device
// firmware that queues reports between polls; an odd-sized one travels alone.
class FakeUsbHandle final : public UsbDevice {
 public:
  FakeUsbHandle(std::shared_ptr<SimulatedDevice> device, std::uint64_t generation)
      : reader_(std::move(device), generation) {}

  ReadResult read(std::uint8_t* buffer, std::size_t capacity, int timeout_ms) override {
    ReadResult r;
    std::vector<std::uint8_t> bytes;
    if (!pending_.empty()) {
      bytes = std::move(pending_);
      pending_.clear();
      r.status = ReadStatus::Data;
    } else {
      r.status = reader_.next(bytes, monotonic_ns() + std::int64_t{timeout_ms} * 1'000'000, false);
    }
    if (r.status == ReadStatus::Gone) r.error = gone_text(reader_.device());
    if (r.status != ReadStatus::Data) return r;
    std::size_t size = std::min(bytes.size(), capacity);
    std::copy_n(bytes.begin(), size, buffer);
    if (bytes.size() == kTrackerReportSize) {
      std::vector<std::uint8_t> more;
      while (size + kTrackerReportSize <= capacity && reader_.next(more, 0, false) == ReadStatus::Data) {
        if (more.size() != kTrackerReportSize) {
          pending_ = std::move(more);
          break;
        }
        std::copy(more.begin(), more.end(), buffer + size);
        size += more.size();
      }
    }
    r.size = size;
    return r;
  }

 private:
  FakeReader reader_;
  std::vector<std::uint8_t> pending_;
};

bool matches(const SimulatedDevice& d, std::uint16_t vendor_id, std::uint16_t product_id) {
  return (vendor_id == 0 || d.config().id.vendor_id == vendor_id) &&
         (product_id == 0 || d.config().id.product_id == product_id);
}

class FakeUsbWatch final : public HotplugWatch {
 public:
  FakeUsbWatch(std::vector<std::shared_ptr<SimulatedDevice>> devices) : devices_(std::move(devices)) {
    last_ = snapshot();
  }
  bool wait(int timeout_ms) override {
    const std::int64_t deadline = monotonic_ns() + std::int64_t{timeout_ms} * 1'000'000;
    for (;;) {
      std::vector<std::uint64_t> now = snapshot();
      if (now != last_) {
        last_ = std::move(now);
        return true;
      }
      const std::int64_t t = monotonic_ns();
      if (t >= deadline) return false;
      sleep_until_ns(std::min(deadline, t + 5'000'000));
    }
  }

 private:
  std::vector<std::uint64_t> snapshot() const {
    std::vector<std::uint64_t> s;
    const std::int64_t now = monotonic_ns();
    for (const auto& d : devices_) {
      std::uint64_t generation = 0;
      const bool present = d->present(now, &generation);
      s.push_back(present ? generation + 1 : 0);
    }
    return s;
  }
  std::vector<std::shared_ptr<SimulatedDevice>> devices_;
  std::vector<std::uint64_t> last_;
};

std::string fake_path(const SimulatedDevice& d, const char* kind) { return std::string(kind) + d.config().name; }

}  // namespace

std::vector<HidDeviceInfo> FakeHidTransport::enumerate(std::uint16_t vendor_id, std::uint16_t product_id) {
  std::vector<HidDeviceInfo> out;
  const std::int64_t now = monotonic_ns();
  for (const auto& d : devices_) {
    if (!matches(*d, vendor_id, product_id) || !d->present(now)) continue;
    HidDeviceInfo info;
    info.vendor_id = d->config().id.vendor_id;
    info.product_id = d->config().id.product_id;
    info.product = d->config().name;
    info.manufacturer = "bodyd simulator";
    if (d->config().protocol == FakeProtocol::Hydra) {
      for (int itf : {kHydraDataInterface, kHydraControlInterface}) {
        info.path = fake_path(*d, "fake-hid:") + "/if" + std::to_string(itf);
        info.interface_number = itf;
        out.push_back(info);
      }
    } else {
      info.path = fake_path(*d, "fake-hid:");
      info.interface_number = 0;
      info.usage_page = 0xFF00;
      info.usage = 0x01;
      out.push_back(info);
    }
  }
  return out;
}

std::unique_ptr<HidDevice> FakeHidTransport::open(const HidDeviceInfo& info, std::string& error) {
  const std::int64_t now = monotonic_ns();
  for (const auto& d : devices_) {
    const std::string base = fake_path(*d, "fake-hid:");
    if (info.path != base && info.path.rfind(base + "/if", 0) != 0) continue;
    std::uint64_t generation = 0;
    if (!d->present(now, &generation)) break;
    const bool control = info.path == base + "/if" + std::to_string(kHydraControlInterface);
    return std::make_unique<FakeHidHandle>(d, generation, control);
  }
  error = "cannot open " + info.path + ": no such device";
  return nullptr;
}

std::vector<UsbDeviceInfo> FakeUsbTransport::enumerate(std::uint16_t vendor_id, std::uint16_t product_id) {
  std::vector<UsbDeviceInfo> out;
  const std::int64_t now = monotonic_ns();
  std::uint8_t address = 1;
  for (const auto& d : devices_) {
    ++address;
    if (!matches(*d, vendor_id, product_id) || !d->present(now)) continue;
    UsbDeviceInfo info;
    info.key = fake_path(*d, "fake-usb:");
    info.bus = 1;
    info.address = address;
    info.vendor_id = d->config().id.vendor_id;
    info.product_id = d->config().id.product_id;
    info.product = d->config().name;
    out.push_back(info);
  }
  return out;
}

std::unique_ptr<UsbDevice> FakeUsbTransport::open(const UsbDeviceInfo& info, std::string& error) {
  const std::int64_t now = monotonic_ns();
  for (const auto& d : devices_) {
    if (info.key != fake_path(*d, "fake-usb:")) continue;
    std::uint64_t generation = 0;
    if (!d->present(now, &generation)) break;
    return std::make_unique<FakeUsbHandle>(d, generation);
  }
  error = info.key + ": no longer present";
  return nullptr;
}

std::unique_ptr<HotplugWatch> FakeUsbTransport::watch(std::uint16_t vendor_id, std::uint16_t product_id) {
  if (!hotplug_) return nullptr;
  std::vector<std::shared_ptr<SimulatedDevice>> watched;
  for (const auto& d : devices_)
    if (matches(*d, vendor_id, product_id)) watched.push_back(d);
  return std::make_unique<FakeUsbWatch>(std::move(watched));
}

// ---------------------------------------------------------------------------------------
std::shared_ptr<SimulatedDeviceSet> make_simulated_device_set(const std::string& bvh_path, std::string& error) {
  try {
    const TrackerTrajectory trajectory(read_bvh(bvh_path));
    auto set = std::make_shared<SimulatedDeviceSet>();
    set->hid = std::make_shared<FakeHidTransport>();
    set->usb = std::make_shared<FakeUsbTransport>(true);
    const std::int64_t now = monotonic_ns();
    auto make = [&](SimulatedDeviceConfig c) {
      auto d = std::make_shared<SimulatedDevice>(trajectory, std::move(c));
      d->plug(now);
      return d;
    };
    SimulatedDeviceConfig all;
    all.name = "simulated bodyd tracker (head, hands)";
    set->hid->add(make(all));
    SimulatedDeviceConfig head;
    head.name = "simulated bodyd headset";
    head.id = {0x1209, 0xB0D2};
    head.roles = {Role::Head};
    set->hid->add(make(head));
    SimulatedDeviceConfig hydra;
    hydra.name = "simulated Razer Hydra";
    hydra.id = {kHydraVendorId, kHydraProductId};
    hydra.protocol = FakeProtocol::Hydra;
    hydra.roles = {Role::LeftHand, Role::RightHand};
    hydra.sim.rate_hz = 60.0;
    set->hid->add(make(hydra));
    SimulatedDeviceConfig usb = all;
    usb.name = "simulated bodyd USB tracker (head, hands)";
    set->usb->add(make(usb));
    return set;
  } catch (const std::exception& e) {
    error = "BODYD_FAKE_DEVICES: " + std::string(e.what());
    return nullptr;
  }
}

std::shared_ptr<SimulatedDeviceSet> simulated_device_set_from_env(std::string& error) {
  static std::mutex mutex;
  static std::shared_ptr<SimulatedDeviceSet> set;
  static std::string set_error;
  static bool made = false;
  const char* path = std::getenv("BODYD_FAKE_DEVICES");
  if (!path || !*path) return nullptr;
  std::lock_guard lock(mutex);
  if (!made) {
    set = make_simulated_device_set(path, set_error);
    made = true;
  }
  if (!set) error = set_error;
  return set;
}

}  // namespace bodyd::drivers
