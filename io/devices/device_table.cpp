// The device table (device_table.h): one row per known vendor/product ID.
#include "bodyd/io/devices/device_table.h"

#include "device_protocol.h"

#include "bodyd/base/require.h"
#include "bodyd/io/devices/hydra.h"

#include <string>

namespace bodyd::drivers {

const std::vector<KnownDevice>& known_devices() {
  // ID, name, protocol, over HID, over USB
  static const std::vector<KnownDevice> devices = {
      // The bodyd tracker report's placeholder pid.codes IDs (docs/hid-tracker.md).
      {{0x1209, 0xB0D1}, "bodyd tracker report", DeviceProtocol::BodydReport, true, true},
      {{0x1209, 0xB0D2}, "bodyd tracker report", DeviceProtocol::BodydReport, true, true},
      {{kHydraVendorId, kHydraProductId}, "Razer Hydra (two hands)", DeviceProtocol::Hydra, true, false},
  };
  return devices;
}

const KnownDevice* known_device(DeviceId id) {
  for (const KnownDevice& d : known_devices())
    if (d.id == id) return &d;
  return nullptr;
}

DeviceProtocol device_protocol_of(DeviceId id) {
  const KnownDevice* d = known_device(id);
  return d ? d->protocol : DeviceProtocol::BodydReport;
}

namespace detail {

const DeviceProtocolRow& device_protocol_row(DeviceProtocol protocol) {
  // protocol, HID opener, fake encoder
  static const DeviceProtocolRow rows[] = {
      {DeviceProtocol::BodydReport, open_bodyd_report_hid, encode_bodyd_report_fake},
      {DeviceProtocol::Hydra, open_hydra_hid, encode_hydra_fake},
  };
  const DeviceProtocolRow* found = nullptr;
  for (const DeviceProtocolRow& row : rows)
    if (row.protocol == protocol) found = &row;
  BODYD_REQUIRE(found, "DeviceProtocol " + std::to_string(static_cast<int>(protocol)) + " has no row in device_table.cpp");
  return *found;
}

}  // namespace detail

}  // namespace bodyd::drivers
