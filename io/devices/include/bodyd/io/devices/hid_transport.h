// The HID transport the HID driver reads through: enumerate, open, read with a timeout,
// send a feature report. make_hidapi_transport() is the real one (hidapi's hidraw
// backend); fake_devices.h has a fake one fed by simulated devices, so tests and demos
// run the real driver without hardware.
//
// Threading: enumerate() and open() may be called from any thread; one HidDevice is read
// by one thread at a time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace bodyd::drivers {

struct HidDeviceInfo {
  std::string path;             // what open() takes, e.g. /dev/hidraw3
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  int interface_number = -1;    // USB interface, -1 when unknown
  std::uint16_t usage_page = 0; // of the first top-level collection, 0 when unknown
  std::uint16_t usage = 0;
  std::string manufacturer;
  std::string product;
  std::string serial;
};

// The outcome of one read: data, nothing within the timeout (a value, not an error), or
// the device is gone (unplugged, I/O error; `error` says which).
enum class ReadStatus { Data, Timeout, Gone };
struct ReadResult {
  ReadStatus status = ReadStatus::Timeout;
  std::size_t size = 0;  // bytes read when Data
  std::string error;     // when Gone
};

class HidDevice {
 public:
  virtual ~HidDevice() = default;
  // Reads one input report (report ID first when the device numbers its reports) into
  // `buffer`, waiting at most `timeout_ms`.
  [[nodiscard]] virtual ReadResult read(std::uint8_t* buffer, std::size_t capacity, int timeout_ms) = 0;
  // Sends a feature report; data[0] is the report ID (0 when the device has none).
  // Empty string on success, else what went wrong.
  [[nodiscard]] virtual std::string send_feature_report(const std::uint8_t* data, std::size_t size) = 0;
};

class HidTransport {
 public:
  virtual ~HidTransport() = default;
  [[nodiscard]] virtual std::string name() const = 0;  // "hidapi-hidraw", "fake"
  // HID devices with this vendor and product ID (0 matches any).
  [[nodiscard]] virtual std::vector<HidDeviceInfo> enumerate(std::uint16_t vendor_id, std::uint16_t product_id) = 0;
  // nullptr and `error` (with what to do, e.g. the udev rule for a permission problem) on failure.
  [[nodiscard]] virtual std::unique_ptr<HidDevice> open(const HidDeviceInfo& info, std::string& error) = 0;
};

// hidapi (hidraw backend). Shared: hidapi's library state is global.
[[nodiscard]] std::shared_ptr<HidTransport> make_hidapi_transport();

}  // namespace bodyd::drivers
