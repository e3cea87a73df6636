// HID driver: reads tracker devices through a HidTransport (hidapi, or a fake one).
//
// It enumerates the configured vendor/product IDs every `rescan_interval_ms`, opens each
// matching device it is not reading yet, and reads each in its own thread with a
// `read_timeout_ms` timeout (so stop() is prompt). Each report is stamped with the host's
// monotonic clock when read, decoded, and pushed. An unplugged device is reported
// (status().last_error, connected=false when none is left) and picked up again when it
// reappears. A device may carry several roles.
//
// Protocols: the one of the ID's row in the device table (device_table.h), else the bodyd
// tracker report (docs/hid-tracker.md), which any ID may stream; the Razer Hydra (1532:0300,
// docs/drivers.md) is switched to motion mode with its feature report.
#pragma once

#include "bodyd/io/devices/device_source.h"
#include "bodyd/io/devices/device_table.h"
#include "bodyd/io/devices/hid_transport.h"
#include "bodyd/io/devices/hydra.h"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace bodyd::drivers {

struct HidSourceOptions {
  std::string name;                  // status name, e.g. "hid:1209:B0D1"
  std::vector<DeviceId> devices;     // the IDs to look for
  std::optional<DeviceProtocol> protocol;  // nullopt: each ID's from the device table (device_protocol_of)
  int read_timeout_ms = 50;
  int rescan_interval_ms = 1000;
  int stall_timeout_ms = 1000;       // an open device silent this long is reported stalled
  HydraOptions hydra;
};

[[nodiscard]] std::unique_ptr<DeviceSource> make_hid_source(const HidSourceOptions& options,
                                                            std::shared_ptr<HidTransport> transport);

}  // namespace bodyd::drivers
