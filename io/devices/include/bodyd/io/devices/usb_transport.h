// The USB transport the USB driver reads through: devices that stream bodyd tracker
// reports (docs/hid-tracker.md) over a vendor-specific (class 0xFF) interface's interrupt
// or bulk IN endpoint. make_libusb_transport() is the real one; fake_devices.h has a fake.
//
// Threading: enumerate(), open() and watch() may be called from any thread; one UsbDevice
// is read by one thread at a time; one HotplugWatch is waited on by one thread.
#pragma once

#include "bodyd/io/devices/hid_transport.h"  // ReadResult

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace bodyd::drivers {

struct UsbDeviceInfo {
  std::string key;              // stable while plugged, e.g. "usb 1-4" (bus 1, port path 4)
  std::uint8_t bus = 0;
  std::uint8_t address = 0;
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  std::string product;          // when readable
};

class UsbDevice {
 public:
  virtual ~UsbDevice() = default;
  // One transfer from the IN endpoint (one or more whole reports), waiting at most `timeout_ms`.
  [[nodiscard]] virtual ReadResult read(std::uint8_t* buffer, std::size_t capacity, int timeout_ms) = 0;
};

// Hotplug notifications for one vendor/product ID.
class HotplugWatch {
 public:
  virtual ~HotplugWatch() = default;
  // Waits up to `timeout_ms` for a device to arrive or leave; true when one did since the last call.
  [[nodiscard]] virtual bool wait(int timeout_ms) = 0;
};

class UsbTransport {
 public:
  virtual ~UsbTransport() = default;
  [[nodiscard]] virtual std::string name() const = 0;  // "libusb", "fake"
  [[nodiscard]] virtual std::vector<UsbDeviceInfo> enumerate(std::uint16_t vendor_id, std::uint16_t product_id) = 0;
  // Opens the device, claims its vendor-specific interface and finds its IN endpoint.
  [[nodiscard]] virtual std::unique_ptr<UsbDevice> open(const UsbDeviceInfo& info, std::string& error) = 0;
  // nullptr when the platform has no hotplug support (then the driver re-enumerates periodically).
  [[nodiscard]] virtual std::unique_ptr<HotplugWatch> watch(std::uint16_t vendor_id, std::uint16_t product_id) = 0;
};

// libusb-1.0. nullptr and `error` when libusb cannot be initialised.
[[nodiscard]] std::shared_ptr<UsbTransport> make_libusb_transport(std::string& error);

}  // namespace bodyd::drivers
