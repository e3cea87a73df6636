// One interface for every tracker source: device drivers (HID, USB), replayed tracker
// logs and simulated devices. The daemon sees only this interface.
//
// Threading: a source runs its own thread between start() and stop(). It hands each
// sample to a SampleSink from that thread; status() may be called from any thread.
// Sources read with timeouts so stop() returns promptly (within ~100 ms).
//
// Time: TrackerSample::t_ns is the time the pose was measured, in the source's time
// base: the host's CLOCK_MONOTONIC stamped at read for live devices, the log's own time
// base for replays (see docs/daemon.md "Time bases"). SourceSample::arrival_ns is always
// the host's CLOCK_MONOTONIC at the moment the source pushed the sample to the sink; the
// daemon measures its latency from it.
#pragma once

#include "bodyd/base/clock.h"
#include "bodyd/motion/tracker.h"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>

namespace bodyd::drivers {

// Host CLOCK_MONOTONIC in nanoseconds (bodyd/base/clock.h): every sample's arrival stamp.
using bodyd::monotonic_ns;

// A sample as a source delivers it.
struct SourceSample {
  TrackerSample sample;
  std::int64_t arrival_ns = 0;    // host monotonic time when pushed to the sink
  std::int64_t device_t_ns = 0;   // the device's own clock, if has_device_time
  bool has_device_time = false;
  std::uint16_t source_index = 0; // which source (index in the daemon's source list)
};

// Where a source puts its samples (the daemon's bounded queue). Thread-safe.
class SampleSink {
 public:
  virtual ~SampleSink() = default;
  // Never blocks: when the sink is full the oldest queued sample is dropped and counted.
  // For live devices, which must keep reading.
  virtual void push(const SourceSample& sample) = 0;
  // Waits up to `timeout` for room; returns false (sample not queued) on timeout. For
  // sources that can wait without losing anything (a file replayed as fast as possible).
  [[nodiscard]] virtual bool push_wait(const SourceSample& sample, std::chrono::nanoseconds timeout) = 0;
};

// What a source reports about itself (status command of the control socket).
struct SourceStatus {
  std::string name;          // the spec it was opened from, e.g. "replay:data/demo/walk.csv"
  bool connected = false;    // running and delivering (a device: present and open)
  bool finished = false;     // a finite source delivered everything (replay without loop)
  std::uint64_t samples = 0; // samples pushed since start
  double rate_hz = 0.0;      // samples per second over the last full second (all roles)
  std::string last_error;    // empty when none
  // Malformed input rejected before it reached the reconstruction (a device's bad reports, a
  // network input's bad packets), in total and, where the source tells them apart, by reason.
  std::uint64_t rejected = 0;
  std::map<std::string, std::uint64_t> rejected_by_reason;
  std::map<std::string, std::uint64_t> counters;  // other source-specific counts (network inputs: datagrams, ignored)
  // Devices that announced themselves (bridge sources): serial -> "role N (name) -> what bodyd
  // does with it" ("head", "left_hand", ... or "not used"). Shown only when not empty.
  std::map<std::string, std::string> devices;
};

class TrackerSource {
 public:
  virtual ~TrackerSource() = default;
  TrackerSource() = default;
  TrackerSource(const TrackerSource&) = delete;
  TrackerSource& operator=(const TrackerSource&) = delete;

  [[nodiscard]] virtual const std::string& name() const = 0;
  // Starts the source's thread, which pushes to `sink` (which must outlive stop()), tagging
  // samples with `source_index`. Returns an empty string, or what went wrong.
  [[nodiscard]] virtual std::string start(SampleSink& sink, std::uint16_t source_index) = 0;
  // Stops and joins the thread. Idempotent; also called by the destructor of implementations.
  virtual void stop() = 0;
  [[nodiscard]] virtual SourceStatus status() const = 0;
};

// Samples per second, measured over windows of about one second. Updated by one thread
// (the source's), read by any.
class RateMeter {
 public:
  void count(std::int64_t now_ns);
  [[nodiscard]] double rate_hz() const { return rate_hz_.load(std::memory_order_relaxed); }

 private:
  std::int64_t window_start_ns_ = 0;
  std::uint64_t window_count_ = 0;
  std::atomic<double> rate_hz_{0.0};
};

}  // namespace bodyd::drivers
