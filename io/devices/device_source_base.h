// Internal: what the HID and USB drivers share. A manager thread enumerates (on a timer or
// a hotplug notification) and opens devices; each open device is read by its own thread,
// with timeouts, until it is gone or the source stops. Protocol decoding lives in the
// OpenDevice implementations (bodyd report, Razer Hydra).
#pragma once

#include "bodyd/io/devices/device_source.h"
#include "bodyd/io/devices/report.h"

#include <atomic>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace bodyd::drivers::detail {

// Shared by the reader threads of one source: the sink, counters and the last error.
class DeviceContext {
 public:
  void push(const TrackerSample& sample, std::int64_t device_t_ns, bool has_device_time);
  void count_report() { reports.fetch_add(1, std::memory_order_relaxed); }
  // A rejected report: counted, logged when the count is a power of two (no log flood).
  void decode_error(const std::string& device, const std::string& what);
  void set_error(std::string text);

  SampleSink* sink = nullptr;
  std::uint16_t source_index = 0;
  std::atomic<std::uint64_t> pushed{0}, reports{0}, decode_errors{0}, lost_reports{0}, clock_jumps{0}, connects{0},
      disconnects{0}, stalls{0};
  std::atomic<int> devices_open{0};

  mutable std::mutex mutex;  // guards the members below
  std::string last_error;
  RateMeter rate;
};

// Unwraps a device's 32-bit microsecond clock into nanoseconds. A restart (the report's
// clock-reset flag), a step backwards or a step forwards of more than a minute counts as a
// jump; device time then continues from where it was (it is informational: t_ns is host time).
class DeviceClock {
 public:
  [[nodiscard]] std::int64_t update(std::uint32_t device_time_us, bool reset_flag, bool& out_jumped);

 private:
  bool have_ = false;
  std::uint32_t last_us_ = 0;
  std::int64_t unwrapped_us_ = 0;
};

// Counts reports missing from a 16-bit (or 8-bit) wrapping sequence.
class SequenceCheck {
 public:
  explicit SequenceCheck(std::uint32_t modulus) : modulus_(modulus) {}
  // Reports lost before this one (0 for the first, a repeat or a step backwards).
  [[nodiscard]] std::uint32_t update(std::uint32_t sequence);

 private:
  std::uint32_t modulus_;
  std::optional<std::uint32_t> last_;
};

// Turns transfers of bodyd tracker reports into samples (HID: one report per read; USB:
// one or more per transfer).
class ReportStream {
 public:
  explicit ReportStream(std::string device) : device_(std::move(device)) {}
  // `allow_several`: split the transfer into 32-byte reports (a slot starting with 0 ends it).
  void handle(const std::uint8_t* data, std::size_t size, std::int64_t t_ns, bool allow_several, DeviceContext& ctx);

 private:
  std::string device_;
  DeviceClock clock_;
  SequenceCheck sequence_{65536};
};

enum class ReadOutcome { Data, Nothing, Gone };

class OpenDevice {
 public:
  virtual ~OpenDevice() = default;
  // Reads once (waiting at most the read timeout) and pushes what it decoded. Gone: the
  // device is unplugged or failing; `error` says why.
  [[nodiscard]] virtual ReadOutcome read_once(DeviceContext& ctx, std::string& error) = 0;
};

struct Candidate {
  std::string key;          // identifies the device while plugged (a path)
  std::string description;  // for logs: "HID 1209:B0D1 /dev/hidraw3 (bodyd tracker)"
  std::function<std::unique_ptr<OpenDevice>(std::string& error)> open;
};

class DeviceSourceBase : public DeviceSource {
 public:
  DeviceSourceBase(std::string name, int rescan_interval_ms, int stall_timeout_ms);
  // Implementations must call stop() in their own destructor (the threads call scan()).
  ~DeviceSourceBase() override = default;

  const std::string& name() const override { return name_; }
  std::string start(SampleSink& sink, std::uint16_t source_index) override;
  void stop() override;
  SourceStatus status() const override;
  DeviceStats stats() const override;

 protected:
  // The devices present now. `problem`: why enumeration failed, if it did.
  [[nodiscard]] virtual std::vector<Candidate> scan(std::string& problem) = 0;
  // Waits up to `timeout_ms` or until stop; true when a device arrived or left (hotplug).
  [[nodiscard]] virtual bool wait_for_change(int timeout_ms);
  // Said (once) when no device is found: what is being waited for and what to do.
  [[nodiscard]] virtual std::string waiting_message() const = 0;
  [[nodiscard]] bool stopping() const { return stop_requested_.load(); }

  int rescan_interval_ms_;

 private:
  struct Reader {
    std::string description;
    std::unique_ptr<OpenDevice> device;
    std::thread thread;
    std::atomic<bool> done{false};
    std::string error;  // written by the reader before done
  };
  void manage();
  void do_scan();
  void reap();
  void read_loop(Reader& reader);

  std::string name_;
  int stall_timeout_ms_;
  std::atomic<bool> stop_requested_{false};
  std::mutex wait_mutex_;
  std::condition_variable wake_;
  std::thread manager_;
  DeviceContext ctx_;
  // Manager thread only.
  std::map<std::string, std::unique_ptr<Reader>> readers_;
  std::map<std::string, std::string> open_errors_;  // last open error per key (logged once)
  bool said_waiting_ = false;
};

// "1209:B0D1" (upper-case hex).
[[nodiscard]] std::string format_device_id(DeviceId id);
// "1209:B0D1, 1532:0300": the ids of a source's devices, for its messages.
[[nodiscard]] std::string format_device_ids(const std::vector<DeviceId>& ids);

}  // namespace bodyd::drivers::detail
