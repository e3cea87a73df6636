#include "bodyd/io/devices/device_list.h"

#include "bodyd/io/devices/device_table.h"

#include "bodyd/io/devices/fake_devices.h"
#include "bodyd/io/open_source.h"
#include "bodyd/io/devices/hid_source.h"
#include "bodyd/io/devices/usb_source.h"
#include "bodyd/io/devices/hydra.h"
#include "device_source_base.h"

#include <algorithm>
#include <charconv>

namespace bodyd::drivers {

std::vector<DeviceId> known_device_ids() {
  std::vector<DeviceId> ids;
  for (const KnownDevice& d : known_devices()) ids.push_back(d.id);
  return ids;
}

std::vector<ListedDevice> list_devices(HidTransport* hid, UsbTransport* usb) {
  std::vector<ListedDevice> out;
  if (hid) {
    for (const HidDeviceInfo& d : hid->enumerate(0, 0)) {
      const DeviceId id{d.vendor_id, d.product_id};
      const KnownDevice* known = known_device(id);
      if (known && !known->hid) known = nullptr;
      const bool bodyd_usage = d.usage_page == 0xFF00 && d.usage == 0x01;
      if (!known && !bodyd_usage) continue;
      const DeviceProtocol protocol = known ? known->protocol : DeviceProtocol::BodydReport;
      if (protocol == DeviceProtocol::Hydra && d.interface_number == kHydraControlInterface)
        continue;  // one line per Hydra
      std::string what = known ? std::string(known->name) : "bodyd tracker report";
      if (!d.product.empty()) what = d.product + ", " + what;
      out.push_back({"hid:" + detail::format_device_id(id), d.path, what});
    }
  }
  if (usb) {
    for (const KnownDevice& known : known_devices()) {
      if (!known.usb) continue;
      for (const UsbDeviceInfo& d : usb->enumerate(known.id.vendor_id, known.id.product_id))
        out.push_back({"usb:" + detail::format_device_id(known.id), d.key,
                       (d.product.empty() ? std::string() : d.product + ", ") + std::string(known.name) + " over USB"});
    }
  }
  return out;
}

std::string no_tracker_device_text(std::string_view demo_recording) {
  std::string hid_ids, usb_ids;
  for (const KnownDevice& d : known_devices()) {
    if (d.hid) hid_ids += (hid_ids.empty() ? "" : ", ") + detail::format_device_id(d.id);
    if (d.usb) usb_ids += (usb_ids.empty() ? "" : ", ") + detail::format_device_id(d.id);
  }
  std::string text =
      "no tracker device found (searched HID devices with the bodyd report usage 0xFF00:0x01 or IDs " + hid_ids +
      ", and USB devices " + usb_ids +
      ").\n"
      "Check that the device is plugged in (lsusb lists it); if it is, the udev rule may be missing: "
      "see docs/drivers.md.\n"
      "A VR headset's trackers come over the network instead (docs/vr-apps.md):\n"
      "  bodyd --source vrchat:   VRChat's OSC trackers (listens on 127.0.0.1:9001)\n"
      "  bodyd --source vmc:      a VMC sender, e.g. Virtual Motion Capture (127.0.0.1:39539)\n";
  if (!demo_recording.empty())
    text += "Without trackers: bodyd --source replay:" + std::string(demo_recording) +
            " (the bundled recording, which bodyd also plays when given no --source), or "
            "bodyd --source sim:FILE.bvh.\n";
  else
    text += "Without trackers: bodyd with no --source plays the bundled recording; or bodyd --source sim:FILE.bvh.\n";
  return text;
}

std::string list_devices_text(std::string_view demo_recording) {
  std::string error;
  std::shared_ptr<SimulatedDeviceSet> fake = simulated_device_set_from_env(error);
  if (!error.empty()) return "error: " + error + "\n";
  std::shared_ptr<HidTransport> hid;
  std::shared_ptr<UsbTransport> usb;
  std::string text;
  if (fake) {
    hid = fake->hid;
    usb = fake->usb;
    text += "(simulated devices: BODYD_FAKE_DEVICES is set)\n";
  } else {
    hid = make_hidapi_transport();
    std::string usb_error;
    usb = make_libusb_transport(usb_error);
    if (!usb) text += "USB devices not searched: " + usb_error + "\n";
  }
  const std::vector<ListedDevice> devices = list_devices(hid.get(), usb.get());
  if (devices.empty()) {
    text += no_tracker_device_text(demo_recording);
    return text;
  }
  for (const ListedDevice& d : devices) text += d.spec + "  " + d.path + "  " + d.description + "\n";
  return text;
}

std::optional<std::vector<DeviceId>> parse_device_ids(std::string_view text, std::string& error) {
  std::vector<DeviceId> ids;
  auto parse_hex = [](std::string_view s, std::uint16_t& out) {
    if (s.empty() || s.size() > 4) return false;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out, 16);
    return ec == std::errc() && end == s.data() + s.size();
  };
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = text.find(',', start);
    const std::string_view item = text.substr(start, comma == std::string_view::npos ? comma : comma - start);
    const std::size_t colon = item.find(':');
    DeviceId id;
    if (colon == std::string_view::npos || !parse_hex(item.substr(0, colon), id.vendor_id) ||
        !parse_hex(item.substr(colon + 1), id.product_id)) {
      error = "\"" + std::string(item) + "\" is not VID:PID (hexadecimal vendor and product ID, e.g. 1209:B0D1)";
      return std::nullopt;
    }
    ids.push_back(id);
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return ids;
}

std::unique_ptr<TrackerSource> open_device_source(std::string_view spec, bool usb, std::string_view argument,
                                                 std::string& error) {
  std::optional<std::vector<DeviceId>> ids = parse_device_ids(argument, error);
  if (!ids) {
    error = "source \"" + std::string(spec) + "\": " + error;
    return nullptr;
  }
  std::shared_ptr<SimulatedDeviceSet> fake = simulated_device_set_from_env(error);
  if (!error.empty()) return nullptr;
  if (usb) {
    std::shared_ptr<UsbTransport> transport = fake ? fake->usb : nullptr;
    if (!transport) transport = make_libusb_transport(error);
    if (!transport) {
      error = "source \"" + std::string(spec) + "\": " + error;
      return nullptr;
    }
    UsbSourceOptions options;
    options.name = std::string(spec);
    options.devices = *ids;
    return make_usb_source(options, transport);
  }
  HidSourceOptions options;
  options.name = std::string(spec);
  options.devices = *ids;
  return make_hid_source(options, fake ? std::shared_ptr<HidTransport>(fake->hid) : make_hidapi_transport());
}

// The registry's factories and check (sources.cpp): hid:VID:PID[,...] and usb:VID:PID[,...].
std::unique_ptr<TrackerSource> open_hid_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  return open_device_source(spec.text, /*usb=*/false, spec.argument, error);
}
std::unique_ptr<TrackerSource> open_usb_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  return open_device_source(spec.text, /*usb=*/true, spec.argument, error);
}
std::string check_device_spec(const SourceSpec& spec) {
  std::string error;
  if (!parse_device_ids(spec.argument, error)) return "source \"" + spec.text + "\": " + error;
  return {};
}

}  // namespace bodyd::drivers
