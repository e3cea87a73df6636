// Internal: the bodyd tracker report read from a HID or USB device (hid_source.cpp,
// usb_source.cpp): read with a timeout, stamp with host time as read, decode (report.h).
#pragma once

#include "bodyd/io/devices/hid_transport.h"  // ReadResult
#include "device_source_base.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace bodyd::drivers::detail {

// `Device`: HidDevice or UsbDevice (a read(buffer, size, timeout_ms) returning ReadResult).
// `transfers` (USB): a read is a transfer of one or more 32-byte reports and an empty one is
// nothing; otherwise (HID) a read is one report, checked for its size.
template <typename Device, std::size_t kBufferSize>
class ReportDevice final : public OpenDevice {
 public:
  ReportDevice(std::unique_ptr<Device> device, std::string description, int timeout_ms, bool transfers)
      : device_(std::move(device)), stream_(std::move(description)), timeout_ms_(timeout_ms), transfers_(transfers) {}

  ReadOutcome read_once(DeviceContext& ctx, std::string& error) override {
    const ReadResult r = device_->read(buffer_.data(), buffer_.size(), timeout_ms_);
    if (r.status == ReadStatus::Gone) {
      error = r.error;
      return ReadOutcome::Gone;
    }
    if (r.status == ReadStatus::Timeout || (transfers_ && r.size == 0)) return ReadOutcome::Nothing;
    const std::int64_t t_ns = monotonic_ns();  // stamped as read (the transfer completed), before decoding
    stream_.handle(buffer_.data(), r.size, t_ns, /*allow_several=*/transfers_, ctx);
    return ReadOutcome::Data;
  }

 private:
  std::unique_ptr<Device> device_;
  ReportStream stream_;
  int timeout_ms_;
  bool transfers_;
  std::array<std::uint8_t, kBufferSize> buffer_{};
};

}  // namespace bodyd::drivers::detail
