// Simulated tracker devices behind fake HID and USB transports. A simulated device
// produces the exact bytes a real one would (bodyd tracker reports, or Razer Hydra
// reports), paced in real time on the host's monotonic clock, from the tracker simulator
// (motion, noise, tracking loss: SimOptions) -- and, on request, misbehaves: short reports,
// garbage, lost reports, stalls, disconnects mid-stream, a device clock that drifts or jumps.
// The drivers read them through the same HidTransport/UsbTransport interfaces as hardware
// and cannot tell the difference.
//
// The daemon uses them when BODYD_FAKE_DEVICES names a BVH clip (simulated_device_set()):
// then `bodyd --source hid:1209:B0D1` reads a simulated device (docs/drivers.md lists them).
#pragma once

#include "bodyd/io/devices/device_source.h"
#include "bodyd/io/devices/device_table.h"
#include "bodyd/io/devices/hid_transport.h"
#include "bodyd/io/devices/hydra.h"
#include "bodyd/io/devices/usb_transport.h"
#include "bodyd/simulators/tracker_sim.h"

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace bodyd::drivers {

// Times are seconds since the device was plugged in (its first report is due then).
struct DeviceFaults {
  double short_report_probability = 0.0;  // report cut to a random shorter length
  double garbage_probability = 0.0;       // random bytes (random length) instead of a report
  double drop_probability = 0.0;          // report lost on the way (its sequence number is skipped)
  double stall_at_s = -1.0;               // silent for stall_s seconds from then (< 0: never)
  double stall_s = 0.0;
  double disconnect_at_s = -1.0;          // unplugged then (< 0: never)
  double reconnect_after_s = -1.0;        // plugged in again this long after (< 0: never)
  double clock_drift_ppm = 0.0;           // device clock runs fast (> 0) or slow
  double clock_jump_at_s = -1.0;          // device clock steps by clock_jump_s then (< 0: never)
  double clock_jump_s = 0.0;
  std::uint64_t seed = 1;
};

// The protocol a simulated device speaks: the device table's (device_table.h), whose rows the
// fake encoder (SimulatedDevice::encode) and the fake HID enumeration follow.
using FakeProtocol = DeviceProtocol;

struct SimulatedDeviceConfig {
  std::string name = "simulated bodyd tracker";
  DeviceId id{0x1209, 0xB0D1};
  FakeProtocol protocol = FakeProtocol::BodydReport;
  std::vector<Role> roles{Role::Head, Role::LeftHand, Role::RightHand};  // Hydra: the two hands
  SimOptions sim;                     // rates (per role), noise, tracking loss, jitter
  DeviceFaults faults;
  bool loop = true;                   // start the clip again at its end
  std::uint32_t clock_start_us = 0;   // device clock at plug-in (near 2^32 to test wrapping)
  bool hydra_starts_in_gamepad_mode = true;  // silent until the motion-mode feature report
  HydraOptions hydra;
};

// One simulated device. Thread-safe.
class SimulatedDevice {
 public:
  // Throws SimError for bad options or a clip without tracked joints.
  SimulatedDevice(const TrackerTrajectory& trajectory, SimulatedDeviceConfig config);

  [[nodiscard]] const SimulatedDeviceConfig& config() const { return config_; }
  // Plugs the device in at host time `now_ns` (reports are due from then) or out.
  void plug(std::int64_t now_ns);
  void unplug();
  // Present (plugged and not in a scheduled disconnect) at `now_ns`, and which plug-in this
  // is (changes on every reconnection, so handles opened before become stale).
  [[nodiscard]] bool present(std::int64_t now_ns, std::uint64_t* out_generation = nullptr) const;

  // The next report due at or before `now_ns` (faults applied), or nullopt; then
  // `out_next_due_ns` is when the next one is due (INT64_MAX: never).
  [[nodiscard]] std::optional<std::vector<std::uint8_t>> poll(std::int64_t now_ns, std::int64_t& out_next_due_ns);
  // A feature report sent to the device (Hydra: the mode switch).
  void feature_report(const std::uint8_t* data, std::size_t size);

  // What the device did (for tests).
  struct Counters {
    std::uint64_t sent = 0, dropped = 0, short_reports = 0, garbage = 0, feature_reports = 0;
    bool motion_mode = false;  // Hydra
  };
  [[nodiscard]] Counters counters() const;

 private:
  struct Item {
    std::int64_t t_ns;                 // within the clip
    std::vector<TrackerSample> samples;  // one (bodyd report) or two (Hydra: left, right)
  };
  [[nodiscard]] std::int64_t due_ns(std::size_t index, std::int64_t loop) const;
  [[nodiscard]] std::vector<std::uint8_t> encode(const Item& item, std::int64_t t_rel_ns);
  [[nodiscard]] bool in_window(std::int64_t t_ns, double at_s, double length_s) const;

  SimulatedDeviceConfig config_;
  std::vector<Item> items_;
  std::int64_t loop_span_ns_ = 0;
  mutable std::mutex mutex_;
  bool plugged_ = false;
  std::int64_t plug_ns_ = 0;
  std::uint64_t generation_ = 0;
  std::size_t next_ = 0;        // next item
  std::int64_t loop_ = 0;
  std::uint16_t sequence_ = 0;
  std::uint64_t rng_state_ = 0;
  Counters counters_;
};

// Fake transports over simulated devices. A device is listed while present.
class FakeHidTransport final : public HidTransport {
 public:
  void add(std::shared_ptr<SimulatedDevice> device) { devices_.push_back(std::move(device)); }
  std::string name() const override { return "fake HID transport"; }
  std::vector<HidDeviceInfo> enumerate(std::uint16_t vendor_id, std::uint16_t product_id) override;
  std::unique_ptr<HidDevice> open(const HidDeviceInfo& info, std::string& error) override;

 private:
  std::vector<std::shared_ptr<SimulatedDevice>> devices_;  // set up before use
};

class FakeUsbTransport final : public UsbTransport {
 public:
  explicit FakeUsbTransport(bool hotplug = true) : hotplug_(hotplug) {}
  void add(std::shared_ptr<SimulatedDevice> device) { devices_.push_back(std::move(device)); }
  std::string name() const override { return "fake USB transport"; }
  std::vector<UsbDeviceInfo> enumerate(std::uint16_t vendor_id, std::uint16_t product_id) override;
  std::unique_ptr<UsbDevice> open(const UsbDeviceInfo& info, std::string& error) override;
  std::unique_ptr<HotplugWatch> watch(std::uint16_t vendor_id, std::uint16_t product_id) override;

 private:
  bool hotplug_;
  std::vector<std::shared_ptr<SimulatedDevice>> devices_;
};

// The simulated devices the daemon offers when BODYD_FAKE_DEVICES=clip.bvh (all plugged
// in when the set is made, looping the clip, with the default SimOptions and no faults):
//   HID 1209:B0D1  bodyd report, head + both hands (one device, three roles), 90 Hz
//   HID 1209:B0D2  bodyd report, head only, 90 Hz
//   HID 1532:0300  simulated Razer Hydra (both hands), 60 Hz, starts in gamepad mode
//   USB 1209:B0D1  bodyd report over a vendor endpoint, head + both hands, 90 Hz
struct SimulatedDeviceSet {
  std::shared_ptr<FakeHidTransport> hid;
  std::shared_ptr<FakeUsbTransport> usb;
};
[[nodiscard]] std::shared_ptr<SimulatedDeviceSet> make_simulated_device_set(const std::string& bvh_path,
                                                                           std::string& error);
// The process's set when the environment variable BODYD_FAKE_DEVICES is set (made once);
// nullptr when it is not set, or on error (then `error` says what).
[[nodiscard]] std::shared_ptr<SimulatedDeviceSet> simulated_device_set_from_env(std::string& error);

}  // namespace bodyd::drivers
