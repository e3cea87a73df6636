// The daemon's statistics for the status command (docs/control.md): counters written by the
// reconstruction thread and read, approximately, by the control thread.
#pragma once

#include "bodyd/io/source.h"
#include "bodyd/motion/tracker.h"

#include <nlohmann/json.hpp>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>

namespace bodyd::daemon {

// The last N durations, written by one thread, read (approximately) by others.
class TimingRing {
 public:
  static constexpr std::size_t kSize = 4096;
  void add(std::int64_t value_ns) {
    const std::uint64_t i = count_.load(std::memory_order_relaxed);
    values_[i % kSize].store(value_ns, std::memory_order_relaxed);
    count_.store(i + 1, std::memory_order_release);
  }
  // {count, window, p50, p99, max} in microseconds over the retained values.
  [[nodiscard]] nlohmann::json summary_us() const;

 private:
  std::array<std::atomic<std::int64_t>, kSize> values_{};
  std::atomic<std::uint64_t> count_{0};
};

// A relaxed counter (statistics only: no ordering with other memory).
struct Counter {
  std::atomic<std::uint64_t> value{0};
  void add(std::uint64_t n = 1) { value.fetch_add(n, std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t get() const { return value.load(std::memory_order_relaxed); }
};

// One source's samples per second role by role (status "sources"[i].rate_hz_by_role): a sink in
// front of the daemon's queue that counts what the source pushes, by arrival time, the way the
// source's own rate_hz counts all its roles together. Pushed to by the source's thread(s), read
// by the control thread.
class RoleRateSink final : public drivers::SampleSink {
 public:
  // A role that has sent nothing for this long reads 0 (a controller switched off).
  static constexpr std::int64_t kSilentNs = 2'000'000'000;

  explicit RoleRateSink(drivers::SampleSink& inner) : inner_(inner) {}
  void push(const drivers::SourceSample& sample) override {
    count(sample);
    inner_.push(sample);
  }
  [[nodiscard]] bool push_wait(const drivers::SourceSample& sample, std::chrono::nanoseconds timeout) override {
    if (!inner_.push_wait(sample, timeout)) return false;
    count(sample);
    return true;
  }
  // Each role's samples per second over its last full second (0 before one, or when silent).
  [[nodiscard]] std::array<double, kRoleCount> rate_hz_by_role(std::int64_t now_ns) const;

 private:
  void count(const drivers::SourceSample& sample);

  struct Meter {
    std::int64_t window_start_ns = 0, last_ns = 0;
    std::uint64_t window_count = 0;
    double rate_hz = 0.0;
  };
  drivers::SampleSink& inner_;
  mutable std::mutex mutex_;
  std::array<Meter, kRoleCount> meters_{};
};

struct PipelineStats {
  Counter samples_in, frames_out, sends_failed, not_ready, encode_failed, skipped_by_rate;
  // Issue 11: samples the reconstructor refused for absurd values (second wall), and restarts of
  // the reconstruction because head time went far back (a replay's time base started over).
  Counter samples_refused, time_restarts;
  Counter body_device_samples_ignored;  // body trackers' device poses (no calibrated mounting yet)
  std::array<Counter, kRoleCount> role_samples;
  TimingRing reconstruct, latency;

  // Writes the pipeline keys of the status reply into `out`.
  void to_json(nlohmann::json& out) const;
};

}  // namespace bodyd::daemon
