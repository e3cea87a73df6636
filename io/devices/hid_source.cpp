// HID driver (hid_source.h): the bodyd report and the Razer Hydra over a HidTransport.
#include "bodyd/io/devices/hid_source.h"

#include "device_protocol.h"
#include "device_source_base.h"
#include "report_device.h"

#include <spdlog/spdlog.h>

#include <algorithm>

namespace bodyd::drivers {
namespace {

using detail::DeviceContext;
using detail::ReadOutcome;

// Large enough for any report a device may send (a longer one is truncated by the
// transport and then rejected for its size).
constexpr std::size_t kReadBufferSize = 256;

// The bodyd report: one report per read.
using BodydHidDevice = detail::ReportDevice<HidDevice, kReadBufferSize>;

// The Hydra streams nothing on its data interface until it is told to enter motion mode
// (feature report on the control interface). As the public drivers do: wait 1 s for
// reports (it may already be in motion mode), then send the feature report, and again
// every 5 s until reports come; switch it back to gamepad mode on close if we switched it.
class HydraHidDevice final : public detail::OpenDevice {
 public:
  HydraHidDevice(std::unique_ptr<HidDevice> data, std::unique_ptr<HidDevice> control, std::string description,
                 const HidSourceOptions& options)
      : data_(std::move(data)),
        control_(std::move(control)),
        description_(std::move(description)),
        options_(options),
        opened_ns_(monotonic_ns()) {}

  ~HydraHidDevice() override {
    if (switched_ && control_) {
      const auto report = hydra_gamepad_mode_feature_report();
      (void)control_->send_feature_report(report.data(), report.size());
    }
  }

  ReadOutcome read_once(DeviceContext& ctx, std::string& error) override {
    const ReadResult r = data_->read(buffer_.data(), buffer_.size(), options_.read_timeout_ms);
    if (r.status == ReadStatus::Gone) {
      error = r.error;
      return ReadOutcome::Gone;
    }
    const std::int64_t t_ns = monotonic_ns();
    if (r.status == ReadStatus::Timeout) {
      maybe_enter_motion_mode(ctx, t_ns);
      return ReadOutcome::Nothing;
    }
    HydraReport report;
    const HydraError e = decode_hydra_report(buffer_.data(), r.size, options_.hydra, report);
    if (e != HydraError::None) {
      ctx.decode_error(description_, describe_hydra_error(e, r.size));
      return ReadOutcome::Data;
    }
    if (!streaming_) spdlog::info("{}: motion reports arriving", description_);
    streaming_ = true;
    ctx.count_report();
    if (const std::uint32_t lost = sequence_.update(report.sequence); lost > 0)
      ctx.lost_reports.fetch_add(lost, std::memory_order_relaxed);
    for (int c = 0; c < 2; ++c) ctx.push(hydra_sample(report, c, options_.hydra, t_ns), 0, false);
    return ReadOutcome::Data;
  }

 private:
  void maybe_enter_motion_mode(DeviceContext& ctx, std::int64_t now_ns) {
    if (streaming_ || !control_) return;
    const std::int64_t since_ns = now_ns - (attempts_ == 0 ? opened_ns_ : last_attempt_ns_);
    const std::int64_t wait_ns = attempts_ == 0 ? 1'000'000'000 : 5'000'000'000;
    if (since_ns < wait_ns) return;
    ++attempts_;
    last_attempt_ns_ = now_ns;
    spdlog::info("{}: switching to motion-controller mode (attempt {})", description_, attempts_);
    const auto report = hydra_motion_mode_feature_report();
    if (std::string e = control_->send_feature_report(report.data(), report.size()); !e.empty()) {
      spdlog::warn("{}: motion-mode feature report failed: {}", description_, e);
      ctx.set_error(description_ + ": motion-mode feature report failed: " + e);
    } else {
      switched_ = true;
    }
  }

  std::unique_ptr<HidDevice> data_, control_;
  std::string description_;
  HidSourceOptions options_;
  std::int64_t opened_ns_;
  std::int64_t last_attempt_ns_ = 0;
  int attempts_ = 0;
  bool streaming_ = false;
  bool switched_ = false;
  detail::SequenceCheck sequence_{256};
  std::array<std::uint8_t, kReadBufferSize> buffer_{};
};

// The HID description of a device for logs: "HID 1209:B0D1 /dev/hidraw3 (bodyd tracker)".
std::string describe(const HidDeviceInfo& info, const char* what) {
  return "HID " + detail::format_device_id({info.vendor_id, info.product_id}) + " " + info.path + " (" +
         (info.product.empty() ? what : info.product) + ")";
}

}  // namespace

namespace detail {

// The bodyd report's opener (device_protocol.h): every interface is a device.
void open_bodyd_report_hid(const HidOpenContext& context, std::vector<HidDeviceInfo>& infos, std::vector<Candidate>& out) {
  for (const HidDeviceInfo& info : infos) {
    const std::string description = describe(info, "bodyd tracker");
    out.push_back({info.path, description, [context, info, description](std::string& error) {
                     std::unique_ptr<HidDevice> d = context.transport->open(info, error);
                     if (!d) return std::unique_ptr<OpenDevice>();
                     return std::unique_ptr<OpenDevice>(
                         std::make_unique<BodydHidDevice>(std::move(d), description, context.options->read_timeout_ms,
                                                         /*transfers=*/false));
                   }});
  }
}

// The Hydra's opener (device_protocol.h). A Hydra shows up as two HID interfaces: 0 streams
// data, 1 takes commands. Pair each data interface with a control interface of the same serial
// number, else in order.
void open_hydra_hid(const HidOpenContext& context, std::vector<HidDeviceInfo>& infos, std::vector<Candidate>& out) {
  std::sort(infos.begin(), infos.end(), [](const auto& a, const auto& b) { return a.path < b.path; });
  std::vector<HidDeviceInfo> data, control;
  for (const HidDeviceInfo& i : infos) {
    if (i.interface_number == kHydraControlInterface)
      control.push_back(i);
    else if (i.interface_number == kHydraDataInterface)
      data.push_back(i);
  }
  if (data.empty() && control.empty()) {
    // Interface numbers unknown: alternate, data first.
    for (std::size_t k = 0; k < infos.size(); ++k) (k % 2 == 0 ? data : control).push_back(infos[k]);
  }
  for (std::size_t k = 0; k < data.size(); ++k) {
    const HidDeviceInfo d = data[k];
    std::optional<HidDeviceInfo> c;
    for (const HidDeviceInfo& ci : control)
      if (!d.serial.empty() && ci.serial == d.serial) c = ci;
    if (!c && k < control.size()) c = control[k];
    const std::string description = describe(d, "Razer Hydra");
    out.push_back({d.path, description, [context, d, c, description](std::string& error) {
                     std::unique_ptr<HidDevice> data_dev = context.transport->open(d, error);
                     if (!data_dev) return std::unique_ptr<OpenDevice>();
                     std::unique_ptr<HidDevice> control_dev;
                     if (c) {
                       std::string control_error;
                       control_dev = context.transport->open(*c, control_error);
                       if (!control_dev)
                         spdlog::warn("{}: cannot open the control interface {}: {} (motion mode cannot be set)",
                                      description, c->path, control_error);
                     }
                     return std::unique_ptr<OpenDevice>(std::make_unique<HydraHidDevice>(
                         std::move(data_dev), std::move(control_dev), description, *context.options));
                   }});
  }
}

}  // namespace detail

namespace {

class HidSource final : public detail::DeviceSourceBase {
 public:
  HidSource(const HidSourceOptions& options, std::shared_ptr<HidTransport> transport)
      : DeviceSourceBase(options.name, options.rescan_interval_ms, options.stall_timeout_ms),
        options_(options),
        transport_(std::move(transport)) {}
  ~HidSource() override { stop(); }

 protected:
  std::vector<detail::Candidate> scan(std::string& /*problem*/) override {
    std::vector<detail::Candidate> out;
    for (const DeviceId id : options_.devices) {
      std::vector<HidDeviceInfo> infos = transport_->enumerate(id.vendor_id, id.product_id);
      const DeviceProtocol protocol = options_.protocol.value_or(device_protocol_of(id));
      detail::device_protocol_row(protocol).open_hid({transport_.get(), &options_}, infos, out);
    }
    return out;
  }

  std::string waiting_message() const override {
    return "no HID device " + detail::format_device_ids(options_.devices) + " found (" + transport_->name() +
           "); waiting for one to be plugged in (bodyd --list-devices shows what is visible; "
           "a device that is plugged in but not listed may need the udev rule, docs/drivers.md)";
  }

 private:
  HidSourceOptions options_;
  std::shared_ptr<HidTransport> transport_;
};

}  // namespace

std::unique_ptr<DeviceSource> make_hid_source(const HidSourceOptions& options, std::shared_ptr<HidTransport> transport) {
  return std::make_unique<HidSource>(options, std::move(transport));
}

}  // namespace bodyd::drivers
