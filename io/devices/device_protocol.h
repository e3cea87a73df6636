// The device protocols (device_table.h's DeviceProtocol): one row each, with the protocol's HID
// opener (hid_source.cpp), which reads with its decoder, and its fake encoder
// (fake_devices.cpp), which makes the bytes a simulated device of the protocol sends.
#pragma once

#include "device_source_base.h"

#include "bodyd/io/devices/device_table.h"
#include "bodyd/io/devices/fake_devices.h"
#include "bodyd/io/devices/hid_source.h"

#include <cstdint>
#include <vector>

namespace bodyd::drivers::detail {

// What an opener may use: the source's transport and options (both outlive the candidates).
struct HidOpenContext {
  HidTransport* transport = nullptr;
  const HidSourceOptions* options = nullptr;
};

// One report of a simulated device: its samples (one per role the report carries), the
// report's sequence number and the time since the device was plugged in.
struct FakeReport {
  const SimulatedDeviceConfig& config;
  const std::vector<TrackerSample>& samples;
  std::uint16_t sequence = 0;
  std::int64_t t_rel_ns = 0;
};

struct DeviceProtocolRow {
  DeviceProtocol protocol;
  // The candidates among the HID interfaces of one ID (a device may be several interfaces);
  // each candidate opens its device(s) and makes the OpenDevice that reads and decodes.
  void (*open_hid)(const HidOpenContext& context, std::vector<HidDeviceInfo>& infos, std::vector<Candidate>& out);
  // The bytes a device of the protocol sends for one report.
  std::vector<std::uint8_t> (*encode_fake)(const FakeReport& report);
};

// The openers (hid_source.cpp) and encoders (fake_devices.cpp).
void open_bodyd_report_hid(const HidOpenContext& context, std::vector<HidDeviceInfo>& infos, std::vector<Candidate>& out);
void open_hydra_hid(const HidOpenContext& context, std::vector<HidDeviceInfo>& infos, std::vector<Candidate>& out);
std::vector<std::uint8_t> encode_bodyd_report_fake(const FakeReport& report);
std::vector<std::uint8_t> encode_hydra_fake(const FakeReport& report);

// The row of `protocol` (every DeviceProtocol has one: device_table.cpp).
[[nodiscard]] const DeviceProtocolRow& device_protocol_row(DeviceProtocol protocol);

}  // namespace bodyd::drivers::detail
