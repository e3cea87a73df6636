#include "device_source_base.h"

#include "bodyd/base/log_rate.h"

#include <spdlog/spdlog.h>

#include <cstdio>

namespace bodyd::drivers::detail {

std::string format_device_id(DeviceId id) {
  char text[16];
  std::snprintf(text, sizeof text, "%04X:%04X", id.vendor_id, id.product_id);
  return text;
}

std::string format_device_ids(const std::vector<DeviceId>& ids) {
  std::string text;
  for (const DeviceId id : ids) text += (text.empty() ? "" : ", ") + format_device_id(id);
  return text;
}

// ---------------------------------------------------------------------------------------
void DeviceContext::push(const TrackerSample& sample, std::int64_t device_t_ns, bool has_device_time) {
  SourceSample s;
  s.sample = sample;
  s.device_t_ns = device_t_ns;
  s.has_device_time = has_device_time;
  s.source_index = source_index;
  s.arrival_ns = monotonic_ns();
  sink->push(s);
  pushed.fetch_add(1, std::memory_order_relaxed);
  std::lock_guard lock(mutex);
  rate.count(s.arrival_ns);
}

void DeviceContext::decode_error(const std::string& device, const std::string& what) {
  const std::uint64_t n = decode_errors.fetch_add(1, std::memory_order_relaxed) + 1;
  const std::string text = device + ": rejected a report: " + what;
  if (log_occurrence(n)) spdlog::warn("{} ({} rejected so far)", text, n);
  set_error(text);
}

void DeviceContext::set_error(std::string text) {
  std::lock_guard lock(mutex);
  last_error = std::move(text);
}

// ---------------------------------------------------------------------------------------
std::int64_t DeviceClock::update(std::uint32_t device_time_us, bool reset_flag, bool& out_jumped) {
  out_jumped = false;
  if (!have_) {
    have_ = true;
    last_us_ = device_time_us;
    unwrapped_us_ = device_time_us;
    return unwrapped_us_ * 1000;
  }
  // Modular difference: correct across the 2^32 us wrap (71.6 minutes).
  const std::uint32_t step = device_time_us - last_us_;
  constexpr std::uint32_t kMaxForwardUs = 60'000'000;
  if (reset_flag || step > kMaxForwardUs) {
    out_jumped = true;  // restarted, stepped backwards (step > 2^31) or far forwards
  } else {
    unwrapped_us_ += step;
  }
  last_us_ = device_time_us;
  return unwrapped_us_ * 1000;
}

std::uint32_t SequenceCheck::update(std::uint32_t sequence) {
  std::uint32_t lost = 0;
  if (last_) {
    const std::uint32_t step = (sequence + modulus_ - *last_) % modulus_;
    // Steps in the lower half are losses (step - 1 reports); the upper half is a repeat or
    // a step backwards (a device restart), not a loss.
    if (step >= 1 && step < modulus_ / 2) lost = step - 1;
  }
  last_ = sequence;
  return lost;
}

void ReportStream::handle(const std::uint8_t* data, std::size_t size, std::int64_t t_ns, bool allow_several,
                          DeviceContext& ctx) {
  std::size_t count = 1;
  std::size_t slot = size;
  if (allow_several && size > kTrackerReportSize) {
    count = (size + kTrackerReportSize - 1) / kTrackerReportSize;
    slot = kTrackerReportSize;
  }
  for (std::size_t i = 0; i < count; ++i) {
    const std::uint8_t* p = data + i * slot;
    const std::size_t n = std::min(slot, size - i * slot);
    if (allow_several && i > 0 && p[0] == 0) break;  // padding
    TrackerReport report;
    const ReportError e = decode_tracker_report(p, n, report);
    if (e != ReportError::None) {
      ctx.decode_error(device_, describe_report_error(e, p, n));
      continue;
    }
    ctx.count_report();
    if (const std::uint32_t lost = sequence_.update(report.sequence); lost > 0)
      ctx.lost_reports.fetch_add(lost, std::memory_order_relaxed);
    bool jumped = false;
    const std::int64_t device_t_ns = clock_.update(report.device_time_us, report.clock_reset, jumped);
    if (jumped) ctx.clock_jumps.fetch_add(1, std::memory_order_relaxed);
    ctx.push(sample_from_report(report, t_ns), device_t_ns, true);
  }
}

// ---------------------------------------------------------------------------------------
DeviceSourceBase::DeviceSourceBase(std::string name, int rescan_interval_ms, int stall_timeout_ms)
    : rescan_interval_ms_(std::max(rescan_interval_ms, 10)),
      name_(std::move(name)),
      stall_timeout_ms_(std::max(stall_timeout_ms, 10)) {}

std::string DeviceSourceBase::start(SampleSink& sink, std::uint16_t source_index) {
  if (manager_.joinable()) return name_ + ": already started";
  ctx_.sink = &sink;
  ctx_.source_index = source_index;
  stop_requested_.store(false);
  manager_ = std::thread([this] { manage(); });
  return {};
}

void DeviceSourceBase::stop() {
  {
    std::lock_guard lock(wait_mutex_);
    stop_requested_.store(true);
  }
  wake_.notify_all();
  if (manager_.joinable()) manager_.join();
}

SourceStatus DeviceSourceBase::status() const {
  SourceStatus s;
  s.name = name_;
  s.connected = ctx_.devices_open.load() > 0;
  s.samples = ctx_.pushed.load(std::memory_order_relaxed);
  s.rejected = ctx_.decode_errors.load(std::memory_order_relaxed);
  std::lock_guard lock(ctx_.mutex);
  s.rate_hz = s.connected ? ctx_.rate.rate_hz() : 0.0;
  s.last_error = ctx_.last_error;
  return s;
}

DeviceStats DeviceSourceBase::stats() const {
  DeviceStats d;
  d.reports = ctx_.reports.load();
  d.decode_errors = ctx_.decode_errors.load();
  d.lost_reports = ctx_.lost_reports.load();
  d.clock_jumps = ctx_.clock_jumps.load();
  d.connects = ctx_.connects.load();
  d.disconnects = ctx_.disconnects.load();
  d.stalls = ctx_.stalls.load();
  d.devices_open = ctx_.devices_open.load();
  return d;
}

bool DeviceSourceBase::wait_for_change(int timeout_ms) {
  std::unique_lock lock(wait_mutex_);
  wake_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [this] { return stop_requested_.load(); });
  return false;
}

void DeviceSourceBase::manage() {
  std::int64_t next_scan_ns = 0;
  bool changed = false;
  while (!stopping()) {
    reap();
    const std::int64_t now = monotonic_ns();
    if (changed || now >= next_scan_ns) {
      do_scan();
      next_scan_ns = now + std::int64_t{rescan_interval_ms_} * 1'000'000;
    }
    const auto until_scan_ms = static_cast<int>((next_scan_ns - monotonic_ns()) / 1'000'000);
    changed = wait_for_change(std::clamp(until_scan_ms, 1, 50));
  }
  for (auto& [key, reader] : readers_) {
    if (reader->thread.joinable()) reader->thread.join();
    if (!reader->done.load()) ctx_.devices_open.fetch_sub(1);
  }
  readers_.clear();
}

void DeviceSourceBase::do_scan() {
  std::string problem;
  std::vector<Candidate> found = scan(problem);
  if (!problem.empty()) ctx_.set_error(problem);
  for (Candidate& c : found) {
    if (readers_.count(c.key)) continue;
    std::string error;
    std::unique_ptr<OpenDevice> device = c.open(error);
    if (!device) {
      auto& last = open_errors_[c.key];
      if (last != error) spdlog::error("{}: cannot open {}: {}", name_, c.description, error);
      last = error;
      ctx_.set_error(c.description + ": " + error);
      continue;
    }
    open_errors_.erase(c.key);
    spdlog::info("{}: opened {}", name_, c.description);
    ctx_.connects.fetch_add(1);
    ctx_.devices_open.fetch_add(1);
    auto reader = std::make_unique<Reader>();
    reader->description = c.description;
    reader->device = std::move(device);
    Reader& r = *reader;
    readers_[c.key] = std::move(reader);
    r.thread = std::thread([this, &r] { read_loop(r); });
    said_waiting_ = false;
  }
  // Said once, until a device is found; after a disconnect the error says which device is awaited.
  if (readers_.empty() && found.empty() && !said_waiting_ && ctx_.connects.load() == 0) {
    const std::string message = waiting_message();
    spdlog::warn("{}: {}", name_, message);
    if (problem.empty()) ctx_.set_error(message);
    said_waiting_ = true;
  }
}

void DeviceSourceBase::reap() {
  for (auto it = readers_.begin(); it != readers_.end();) {
    Reader& r = *it->second;
    if (!r.done.load()) {
      ++it;
      continue;
    }
    r.thread.join();
    spdlog::warn("{}: {}", name_, r.error);
    it = readers_.erase(it);
  }
}

void DeviceSourceBase::read_loop(Reader& reader) {
  std::int64_t last_data_ns = monotonic_ns();
  bool stalled = false;
  const std::int64_t stall_ns = std::int64_t{stall_timeout_ms_} * 1'000'000;
  while (!stopping()) {
    std::string error;
    const ReadOutcome outcome = reader.device->read_once(ctx_, error);
    const std::int64_t now = monotonic_ns();
    if (outcome == ReadOutcome::Gone) {
      reader.device.reset();  // close before the manager may reopen the same device
      reader.error = reader.description + ": " + (error.empty() ? "device gone" : error) +
                     "; waiting for it to come back";
      // Reported, then counted, before `connected` turns false, so a reader of status() sees why.
      ctx_.set_error(reader.error);
      ctx_.disconnects.fetch_add(1);
      ctx_.devices_open.fetch_sub(1);
      reader.done.store(true);
      return;
    }
    if (outcome == ReadOutcome::Data) {
      if (stalled) spdlog::info("{}: {} is sending again", name_, reader.description);
      stalled = false;
      last_data_ns = now;
    } else if (!stalled && now - last_data_ns > stall_ns) {
      stalled = true;
      const std::string text = reader.description + ": no reports for " + std::to_string(stall_timeout_ms_) +
                               " ms (device stalled or not streaming)";
      spdlog::warn("{}: {}", name_, text);
      // The error is set before the counter moves, so a reader who sees the stall counted also sees why.
      ctx_.set_error(text);
      ctx_.stalls.fetch_add(1);
    }
  }
}

}  // namespace bodyd::drivers::detail
