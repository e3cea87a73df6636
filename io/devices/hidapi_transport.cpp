// The real HID transport: hidapi's hidraw backend (Linux).
#include "bodyd/io/devices/hid_transport.h"

#include <hidapi/hidapi.h>

#include <cerrno>
#include <cstring>
#include <mutex>

#include <unistd.h>

namespace bodyd::drivers {
namespace {

std::string narrow(const wchar_t* text) {
  std::string out;
  if (!text) return out;
  for (; *text; ++text) out += (*text > 0 && *text < 128) ? static_cast<char>(*text) : '?';
  return out;
}

// What to do when a hidraw node exists but cannot be opened.
std::string permission_hint(const std::string& path) {
  if (::access(path.c_str(), R_OK | W_OK) == 0 || errno != EACCES) return {};
  return "permission denied on " + path +
         ": install bodyd's udev rule (sudo cp packaging/udev/70-bodyd.rules /etc/udev/rules.d/ && "
         "sudo udevadm control --reload-rules && sudo udevadm trigger), then unplug and replug the device "
         "(docs/drivers.md)";
}

class HidapiDevice final : public HidDevice {
 public:
  HidapiDevice(hid_device* device, std::string path) : device_(device), path_(std::move(path)) {}
  ~HidapiDevice() override { hid_close(device_); }

  ReadResult read(std::uint8_t* buffer, std::size_t capacity, int timeout_ms) override {
    ReadResult r;
    const int n = hid_read_timeout(device_, buffer, capacity, timeout_ms);
    if (n < 0) {
      r.status = ReadStatus::Gone;
      r.error = "read failed on " + path_ + ": " + narrow(hid_error(device_)) + " (unplugged?)";
    } else if (n == 0) {
      r.status = ReadStatus::Timeout;
    } else {
      r.status = ReadStatus::Data;
      r.size = static_cast<std::size_t>(n);
    }
    return r;
  }

  std::string send_feature_report(const std::uint8_t* data, std::size_t size) override {
    if (hid_send_feature_report(device_, data, size) < 0)
      return "feature report to " + path_ + " failed: " + narrow(hid_error(device_));
    return {};
  }

 private:
  hid_device* device_;
  std::string path_;
};

class HidapiTransport final : public HidTransport {
 public:
  HidapiTransport() { init_error_ = hid_init() != 0; }
  ~HidapiTransport() override { hid_exit(); }

  std::string name() const override { return "hidapi-hidraw"; }

  std::vector<HidDeviceInfo> enumerate(std::uint16_t vendor_id, std::uint16_t product_id) override {
    std::vector<HidDeviceInfo> out;
    if (init_error_) return out;
    std::lock_guard lock(mutex_);  // hidapi's enumeration and error state are global
    hid_device_info* list = hid_enumerate(vendor_id, product_id);
    for (hid_device_info* d = list; d; d = d->next) {
      HidDeviceInfo info;
      info.path = d->path ? d->path : "";
      info.vendor_id = d->vendor_id;
      info.product_id = d->product_id;
      info.interface_number = d->interface_number;
      info.usage_page = d->usage_page;
      info.usage = d->usage;
      info.manufacturer = narrow(d->manufacturer_string);
      info.product = narrow(d->product_string);
      info.serial = narrow(d->serial_number);
      out.push_back(std::move(info));
    }
    hid_free_enumeration(list);
    return out;
  }

  std::unique_ptr<HidDevice> open(const HidDeviceInfo& info, std::string& error) override {
    if (init_error_) {
      error = "hidapi could not be initialised (hid_init failed)";
      return nullptr;
    }
    std::lock_guard lock(mutex_);
    hid_device* device = hid_open_path(info.path.c_str());
    if (!device) {
      error = permission_hint(info.path);
      if (error.empty()) error = "cannot open " + info.path + ": " + narrow(hid_error(nullptr));
      return nullptr;
    }
    hid_set_nonblocking(device, 0);
    return std::make_unique<HidapiDevice>(device, info.path);
  }

 private:
  bool init_error_ = false;
  std::mutex mutex_;
};

}  // namespace

std::shared_ptr<HidTransport> make_hidapi_transport() {
  // One per process: hid_init/hid_exit manage global state.
  static std::mutex mutex;
  static std::weak_ptr<HidTransport> shared;
  std::lock_guard lock(mutex);
  std::shared_ptr<HidTransport> t = shared.lock();
  if (!t) {
    t = std::make_shared<HidapiTransport>();
    shared = t;
  }
  return t;
}

}  // namespace bodyd::drivers
