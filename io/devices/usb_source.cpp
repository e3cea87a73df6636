// USB driver (usb_source.h): bodyd reports over a vendor endpoint, through a UsbTransport.
#include "bodyd/io/devices/usb_source.h"

#include "device_source_base.h"
#include "report_device.h"

namespace bodyd::drivers {
namespace {

// A full-speed bulk packet is 64 bytes, high-speed 512; a transfer of up to 16 reports.
constexpr std::size_t kTransferSize = 512;

// The bodyd report: transfers of one or more reports.
using BodydUsbDevice = detail::ReportDevice<UsbDevice, kTransferSize>;

class UsbSource final : public detail::DeviceSourceBase {
 public:
  UsbSource(const UsbSourceOptions& options, std::shared_ptr<UsbTransport> transport)
      : DeviceSourceBase(options.name, options.rescan_interval_ms, options.stall_timeout_ms),
        options_(options),
        transport_(std::move(transport)) {
    for (const DeviceId id : options_.devices)
      if (auto w = transport_->watch(id.vendor_id, id.product_id)) watches_.push_back(std::move(w));
    // With hotplug notifications, enumeration on a timer is only a safety net.
    if (!watches_.empty() && watches_.size() == options_.devices.size()) rescan_interval_ms_ *= 5;
  }
  ~UsbSource() override { stop(); }

  [[nodiscard]] bool has_hotplug() const { return !watches_.empty(); }

 protected:
  std::vector<detail::Candidate> scan(std::string& /*problem*/) override {
    std::vector<detail::Candidate> out;
    for (const DeviceId id : options_.devices) {
      for (const UsbDeviceInfo& info : transport_->enumerate(id.vendor_id, id.product_id)) {
        const std::string description = "USB " + detail::format_device_id({info.vendor_id, info.product_id}) + " " +
                                        info.key + " (" + (info.product.empty() ? "bodyd tracker" : info.product) +
                                        ")";
        out.push_back({info.key, description, [this, info, description](std::string& error) {
                         std::unique_ptr<UsbDevice> d = transport_->open(info, error);
                         if (!d) return std::unique_ptr<detail::OpenDevice>();
                         return std::unique_ptr<detail::OpenDevice>(
                             std::make_unique<BodydUsbDevice>(std::move(d), description, options_.read_timeout_ms,
                                                              /*transfers=*/true));
                       }});
      }
    }
    return out;
  }

  bool wait_for_change(int timeout_ms) override {
    if (watches_.empty()) return DeviceSourceBase::wait_for_change(timeout_ms);
    bool changed = false;
    const int each_ms = std::max(1, timeout_ms / static_cast<int>(watches_.size()));
    for (auto& w : watches_) changed = w->wait(each_ms) || changed;
    return changed;
  }

  std::string waiting_message() const override {
    return "no USB device " + detail::format_device_ids(options_.devices) + " found (" + transport_->name() + ", " +
           (watches_.empty() ? "re-enumerating every " + std::to_string(rescan_interval_ms_) + " ms"
                             : std::string("hotplug")) +
           "); waiting for one to be plugged in (bodyd --list-devices shows what is visible)";
  }

 private:
  UsbSourceOptions options_;
  std::shared_ptr<UsbTransport> transport_;
  std::vector<std::unique_ptr<HotplugWatch>> watches_;
};

}  // namespace

std::unique_ptr<DeviceSource> make_usb_source(const UsbSourceOptions& options, std::shared_ptr<UsbTransport> transport) {
  return std::make_unique<UsbSource>(options, std::move(transport));
}

}  // namespace bodyd::drivers
