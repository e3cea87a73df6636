// The device table (device_table.h): one row per known vendor/product ID.
#include "bodyd/drivers/device_table.h"

#include "bodyd/drivers/hydra.h"

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

}  // namespace bodyd::drivers
