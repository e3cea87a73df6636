// The tracker devices bodyd knows: one row per USB vendor/product ID (io/devices/device_table.cpp).
// The rows drive what `bodyd --list-devices` lists and says it searched, which protocol a
// hid:VID:PID spec reads (hid_source.h), and the udev rule: packaging/udev/70-bodyd.rules gives
// access to exactly the rows' IDs over their transports, which
// tests/drivers/source_registry_test.cpp checks (DeviceTable.TheUdevRuleGrantsExactlyTheTable).
//
// How to add a device (docs/architecture.md, "A new tracker source"):
//   - of a protocol bodyd reads already (a new ID streaming the bodyd report): one row, and its
//     line in the udev rule;
//   - of a new protocol, also: its DeviceProtocol value and its row in the protocol rows
//     (device_protocol_row in device_table.cpp; the row type is io/devices/device_protocol.h):
//     its HID opener (next to the others in hid_source.cpp: it pairs interfaces and makes the
//     OpenDevice that reads with the protocol's decoder) and its fake encoder (next to the
//     others in fake_devices.cpp: the bytes a device sends for one report); the decoder's pure
//     functions in a file of their own (like hydra.h), fuzzed (tests/drivers/fuzz_targets.h).
//     A protocol whose reports carry several roles or whose device is several interfaces (the
//     Hydra) also needs its case where the simulated devices pair samples and list interfaces
//     (fake_devices.cpp).
#pragma once

#include "bodyd/io/devices/device_source.h"

#include <cstdint>
#include <string_view>
#include <vector>

namespace bodyd::drivers {

// How a device's reports are read and simulated.
enum class DeviceProtocol : std::uint8_t {
  BodydReport,  // the bodyd tracker report (docs/hid-tracker.md), over HID or a USB endpoint
  Hydra,        // the Razer Hydra's reports (hydra.h), two HID interfaces, motion mode by feature report
};

struct KnownDevice {
  DeviceId id;
  std::string_view name;    // what bodyd --list-devices says it is, e.g. "Razer Hydra (two hands)"
  DeviceProtocol protocol;  // how it is read (hid:, usb:) and simulated (fake_devices.h): its row, device_protocol.h
  bool hid = true;          // read over HID (hid:VID:PID); the udev rule's SUBSYSTEM=="hidraw" line
  bool usb = false;         // read over USB (usb:VID:PID); the udev rule's SUBSYSTEM=="usb" line
};

// The device table, in the order --list-devices' "searched" text names them.
[[nodiscard]] const std::vector<KnownDevice>& known_devices();
// The row of `id`, or nullptr.
[[nodiscard]] const KnownDevice* known_device(DeviceId id);
// The protocol a device of `id` speaks when the spec does not say: its row's, else the bodyd
// report (any ID may stream it).
[[nodiscard]] DeviceProtocol device_protocol_of(DeviceId id);

}  // namespace bodyd::drivers
