// USB driver: devices that stream the bodyd tracker report (docs/hid-tracker.md) over a
// vendor-specific interrupt or bulk IN endpoint, read through a UsbTransport (libusb, or
// a fake one). A transfer holds one or more whole 32-byte reports (a slot starting with
// byte 0 is padding and ends the transfer).
//
// With hotplug support (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG)) a device arriving
// triggers an immediate re-enumeration; without it, and as a safety net, the driver
// re-enumerates every `rescan_interval_ms`. Reads use `read_timeout_ms`; each transfer is
// stamped with the host monotonic clock when it completes.
#pragma once

#include "bodyd/io/devices/device_source.h"
#include "bodyd/io/devices/usb_transport.h"

#include <memory>
#include <string>
#include <vector>

namespace bodyd::drivers {

struct UsbSourceOptions {
  std::string name;               // status name, e.g. "usb:1209:B0D1"
  std::vector<DeviceId> devices;
  int read_timeout_ms = 50;
  int rescan_interval_ms = 1000;  // without hotplug; with hotplug 5x longer
  int stall_timeout_ms = 1000;
};

[[nodiscard]] std::unique_ptr<DeviceSource> make_usb_source(const UsbSourceOptions& options,
                                                            std::shared_ptr<UsbTransport> transport);

}  // namespace bodyd::drivers
