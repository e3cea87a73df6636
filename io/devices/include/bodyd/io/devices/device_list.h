// What tracker devices are visible (bodyd --list-devices), and the device-source specs
// (hid:VID:PID, usb:VID:PID) parsed into ID lists.
#pragma once

#include "bodyd/io/devices/device_source.h"
#include "bodyd/io/devices/hid_transport.h"
#include "bodyd/io/devices/usb_transport.h"

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::drivers {

struct ListedDevice {
  std::string spec;         // what to pass to --source, e.g. "hid:1209:B0D1"
  std::string path;         // hidraw path or USB bus/port
  std::string description;  // product and protocol
};

// IDs bodyd knows: the bodyd tracker report's default IDs (1209:B0D1, 1209:B0D2) and the
// Razer Hydra (1532:0300).
[[nodiscard]] std::vector<DeviceId> known_device_ids();

// HID devices with a known ID or the bodyd report's usage (page 0xFF00, usage 1), and USB
// devices with a known ID. Either transport may be null (not searched).
[[nodiscard]] std::vector<ListedDevice> list_devices(HidTransport* hid, UsbTransport* usb);

// The text bodyd --list-devices prints: one line per device, or no_tracker_device_text().
// Uses the simulated devices when BODYD_FAKE_DEVICES is set. `demo_recording`: the path of the
// bundled recording (data/demo/walk.csv as found; "" if unknown), named as the thing to try.
[[nodiscard]] std::string list_devices_text(std::string_view demo_recording = {});

// "no tracker device found", what was searched and what to check, then the inputs a headset
// user needs instead (vrchat:, vmc:) and the bundled recording to try without trackers.
[[nodiscard]] std::string no_tracker_device_text(std::string_view demo_recording);

// "1209:B0D1" or "1209:B0D1,1532:0300" (hex, 1-4 digits each). nullopt and `error` when malformed.
[[nodiscard]] std::optional<std::vector<DeviceId>> parse_device_ids(std::string_view text, std::string& error);

// Opens the HID (usb=false) or USB driver for a spec's "VID:PID[,VID:PID...]" argument,
// over the real transport, or the simulated devices when BODYD_FAKE_DEVICES is set.
// A device that is absent is not an error: the source waits for it. nullptr and `error`
// when the argument is malformed or the transport cannot start.
[[nodiscard]] std::unique_ptr<TrackerSource> open_device_source(std::string_view spec, bool usb,
                                                                 std::string_view argument, std::string& error);

}  // namespace bodyd::drivers
