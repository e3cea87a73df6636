// The real USB transport: libusb-1.0. Devices expose a vendor-specific (class 0xFF)
// interface with an interrupt or bulk IN endpoint carrying bodyd tracker reports.
#include "bodyd/io/devices/usb_transport.h"

#include <libusb.h>

#include <atomic>
#include <cstdio>
#include <mutex>

namespace bodyd::drivers {
namespace {

constexpr char kUdevHint[] =
    "install bodyd's udev rule (sudo cp packaging/udev/70-bodyd.rules /etc/udev/rules.d/ && "
    "sudo udevadm control --reload-rules && sudo udevadm trigger), then unplug and replug the device "
    "(docs/drivers.md)";

std::string device_key(libusb_device* dev) {
  std::uint8_t ports[8];
  const int n = libusb_get_port_numbers(dev, ports, 8);
  std::string key = "usb " + std::to_string(libusb_get_bus_number(dev)) + "-";
  for (int i = 0; i < n; ++i) key += (i ? "." : "") + std::to_string(ports[i]);
  if (n <= 0) key += "addr" + std::to_string(libusb_get_device_address(dev));
  return key;
}

class LibusbContext {
 public:
  explicit LibusbContext(libusb_context* ctx) : ctx_(ctx) {}
  ~LibusbContext() { libusb_exit(ctx_); }
  libusb_context* get() const { return ctx_; }

 private:
  libusb_context* ctx_;
};

class LibusbDevice final : public UsbDevice {
 public:
  LibusbDevice(std::shared_ptr<LibusbContext> ctx, libusb_device_handle* handle, int interface, std::uint8_t endpoint,
               bool interrupt, std::string key)
      : ctx_(std::move(ctx)), handle_(handle), interface_(interface), endpoint_(endpoint), interrupt_(interrupt),
        key_(std::move(key)) {}
  ~LibusbDevice() override {
    libusb_release_interface(handle_, interface_);
    libusb_close(handle_);
  }

  ReadResult read(std::uint8_t* buffer, std::size_t capacity, int timeout_ms) override {
    int transferred = 0;
    const int length = static_cast<int>(capacity);
    const int rc = interrupt_ ? libusb_interrupt_transfer(handle_, endpoint_, buffer, length, &transferred,
                                                          static_cast<unsigned>(timeout_ms))
                              : libusb_bulk_transfer(handle_, endpoint_, buffer, length, &transferred,
                                                     static_cast<unsigned>(timeout_ms));
    ReadResult r;
    if (rc == 0 || (rc == LIBUSB_ERROR_TIMEOUT && transferred > 0)) {
      r.status = transferred > 0 ? ReadStatus::Data : ReadStatus::Timeout;
      r.size = static_cast<std::size_t>(transferred);
    } else if (rc == LIBUSB_ERROR_TIMEOUT || rc == LIBUSB_ERROR_INTERRUPTED || rc == LIBUSB_ERROR_OVERFLOW) {
      r.status = ReadStatus::Timeout;  // overflow: the device sent more than a transfer holds; dropped
    } else {
      r.status = ReadStatus::Gone;
      r.error = "transfer from " + key_ + " failed: " + libusb_strerror(rc) +
                (rc == LIBUSB_ERROR_NO_DEVICE ? " (unplugged)" : "");
    }
    return r;
  }

 private:
  std::shared_ptr<LibusbContext> ctx_;  // outlives the handle
  libusb_device_handle* handle_;
  int interface_;
  std::uint8_t endpoint_;
  bool interrupt_;
  std::string key_;
};

class LibusbWatch final : public HotplugWatch {
 public:
  LibusbWatch(std::shared_ptr<LibusbContext> ctx, int vendor_id, int product_id) : ctx_(std::move(ctx)) {
    const int rc = libusb_hotplug_register_callback(
        ctx_->get(),
        static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
        static_cast<libusb_hotplug_flag>(0), vendor_id ? vendor_id : LIBUSB_HOTPLUG_MATCH_ANY,
        product_id ? product_id : LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY, &LibusbWatch::on_event, this,
        &handle_);
    registered_ = rc == LIBUSB_SUCCESS;
  }
  ~LibusbWatch() override {
    if (registered_) libusb_hotplug_deregister_callback(ctx_->get(), handle_);
  }
  bool registered() const { return registered_; }

  bool wait(int timeout_ms) override {
    timeval tv{timeout_ms / 1000, (timeout_ms % 1000) * 1000};
    // Delivers hotplug callbacks (they run inside event handling, on this thread or on a
    // thread doing a synchronous transfer).
    libusb_handle_events_timeout_completed(ctx_->get(), &tv, nullptr);
    return changed_.exchange(false);
  }

 private:
  static int LIBUSB_CALL on_event(libusb_context*, libusb_device*, libusb_hotplug_event, void* self) {
    static_cast<LibusbWatch*>(self)->changed_.store(true);
    return 0;  // stay registered
  }

  std::shared_ptr<LibusbContext> ctx_;
  libusb_hotplug_callback_handle handle_ = 0;
  bool registered_ = false;
  std::atomic<bool> changed_{false};
};

class LibusbTransport final : public UsbTransport {
 public:
  explicit LibusbTransport(std::shared_ptr<LibusbContext> ctx) : ctx_(std::move(ctx)) {}

  std::string name() const override { return "libusb"; }

  std::vector<UsbDeviceInfo> enumerate(std::uint16_t vendor_id, std::uint16_t product_id) override {
    std::vector<UsbDeviceInfo> out;
    libusb_device** list = nullptr;
    const ssize_t n = libusb_get_device_list(ctx_->get(), &list);
    for (ssize_t i = 0; i < n; ++i) {
      libusb_device_descriptor desc{};
      if (libusb_get_device_descriptor(list[i], &desc) != 0) continue;
      if ((vendor_id && desc.idVendor != vendor_id) || (product_id && desc.idProduct != product_id)) continue;
      UsbDeviceInfo info;
      info.key = device_key(list[i]);
      info.bus = libusb_get_bus_number(list[i]);
      info.address = libusb_get_device_address(list[i]);
      info.vendor_id = desc.idVendor;
      info.product_id = desc.idProduct;
      out.push_back(std::move(info));
    }
    if (list) libusb_free_device_list(list, 1);
    return out;
  }

  std::unique_ptr<UsbDevice> open(const UsbDeviceInfo& info, std::string& error) override {
    libusb_device** list = nullptr;
    const ssize_t n = libusb_get_device_list(ctx_->get(), &list);
    libusb_device* found = nullptr;
    for (ssize_t i = 0; i < n && !found; ++i)
      if (device_key(list[i]) == info.key) found = libusb_ref_device(list[i]);
    if (list) libusb_free_device_list(list, 1);
    if (!found) {
      error = info.key + ": no longer present";
      return nullptr;
    }
    std::unique_ptr<UsbDevice> device = open_device(found, info, error);
    libusb_unref_device(found);
    return device;
  }

  std::unique_ptr<HotplugWatch> watch(std::uint16_t vendor_id, std::uint16_t product_id) override {
    if (!libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG)) return nullptr;
    auto w = std::make_unique<LibusbWatch>(ctx_, vendor_id, product_id);
    if (!w->registered()) return nullptr;
    return w;
  }

 private:
  std::unique_ptr<UsbDevice> open_device(libusb_device* dev, const UsbDeviceInfo& info, std::string& error) {
    libusb_config_descriptor* config = nullptr;
    if (int rc = libusb_get_active_config_descriptor(dev, &config); rc != 0) {
      error = info.key + ": cannot read the configuration descriptor: " + libusb_strerror(rc);
      return nullptr;
    }
    int interface = -1;
    std::uint8_t endpoint = 0;
    bool interrupt = false;
    for (int i = 0; i < config->bNumInterfaces && interface < 0; ++i) {
      const libusb_interface& itf = config->interface[i];
      if (itf.num_altsetting < 1) continue;
      const libusb_interface_descriptor& alt = itf.altsetting[0];
      if (alt.bInterfaceClass != LIBUSB_CLASS_VENDOR_SPEC) continue;
      for (int e = 0; e < alt.bNumEndpoints; ++e) {
        const libusb_endpoint_descriptor& ep = alt.endpoint[e];
        const int type = ep.bmAttributes & LIBUSB_TRANSFER_TYPE_MASK;
        if ((ep.bEndpointAddress & LIBUSB_ENDPOINT_IN) &&
            (type == LIBUSB_TRANSFER_TYPE_INTERRUPT || type == LIBUSB_TRANSFER_TYPE_BULK)) {
          interface = alt.bInterfaceNumber;
          endpoint = ep.bEndpointAddress;
          interrupt = type == LIBUSB_TRANSFER_TYPE_INTERRUPT;
          break;
        }
      }
    }
    libusb_free_config_descriptor(config);
    if (interface < 0) {
      error = info.key +
              ": no vendor-specific interface (class 0xFF) with an interrupt or bulk IN endpoint; "
              "is this a bodyd USB tracker (docs/hid-tracker.md)?";
      return nullptr;
    }
    libusb_device_handle* handle = nullptr;
    if (int rc = libusb_open(dev, &handle); rc != 0) {
      error = "cannot open " + info.key + ": " + libusb_strerror(rc);
      if (rc == LIBUSB_ERROR_ACCESS) error += "; " + std::string(kUdevHint);
      return nullptr;
    }
    libusb_set_auto_detach_kernel_driver(handle, 1);
    if (int rc = libusb_claim_interface(handle, interface); rc != 0) {
      error = "cannot claim interface " + std::to_string(interface) + " of " + info.key + ": " + libusb_strerror(rc) +
              (rc == LIBUSB_ERROR_BUSY ? " (another program is using it)" : "");
      libusb_close(handle);
      return nullptr;
    }
    return std::make_unique<LibusbDevice>(ctx_, handle, interface, endpoint, interrupt, info.key);
  }

  std::shared_ptr<LibusbContext> ctx_;
};

}  // namespace

std::shared_ptr<UsbTransport> make_libusb_transport(std::string& error) {
  libusb_context* ctx = nullptr;
  if (int rc = libusb_init(&ctx); rc != 0) {
    error = std::string("libusb could not be initialised: ") + libusb_strerror(rc);
    return nullptr;
  }
  return std::make_shared<LibusbTransport>(std::make_shared<LibusbContext>(ctx));
}

}  // namespace bodyd::drivers
