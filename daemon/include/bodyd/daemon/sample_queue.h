// The bounded queue between the tracker sources and the reconstruction thread.
//
// Many producers (one thread per source), one consumer. Storage is allocated once, at
// construction; push never blocks: when the queue is full the oldest sample is dropped
// and counted (a live device must keep reading, and the newest sample matters most).
// push_wait lets a source that can wait (a file replayed as fast as possible) wait for room
// instead, so nothing is lost. A mutex + condition variable: the critical sections are a
// few copies, far below the reconstruction time, and the consumer sleeps while idle.
//
// Stale samples (issue 11): when the consumer falls behind (a reconstruction slower than the
// trackers), a full queue would hold seconds of old samples and every pose would come that
// late. With max_age > 0, pop() first drops the oldest samples that arrived more than max_age
// before the newest one queued (SourceSample::arrival_ns), counted in dropped_stale(), so a
// pose is never built from a sample more than max_age behind the trackers. Samples pushed with
// push_wait (a lossless replay) are never dropped for their age.
#pragma once

#include "bodyd/io/source.h"

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <vector>

namespace bodyd::daemon {

class SampleQueue final : public drivers::SampleSink {
 public:
  // max_age: zero = keep every sample until the queue is full. A capacity of 0 or a negative
  // max_age is a bug (the Daemon clamps the configured ones).
  explicit SampleQueue(std::size_t capacity, std::chrono::nanoseconds max_age = std::chrono::nanoseconds::zero());

  void push(const drivers::SourceSample& sample) override;
  [[nodiscard]] bool push_wait(const drivers::SourceSample& sample, std::chrono::nanoseconds timeout) override;

  // Takes the oldest sample that is not stale (see above); waits up to `timeout` for one.
  // False on timeout.
  [[nodiscard]] bool pop(drivers::SourceSample& out, std::chrono::nanoseconds timeout);

  [[nodiscard]] std::size_t size() const;
  [[nodiscard]] std::size_t capacity() const { return ring_.size(); }
  [[nodiscard]] std::uint64_t pushed() const;   // samples accepted (including later dropped ones)
  [[nodiscard]] std::uint64_t dropped() const;  // samples dropped because the queue was full
  [[nodiscard]] std::uint64_t dropped_stale() const;  // samples dropped as more than max_age behind
  [[nodiscard]] std::chrono::nanoseconds max_age() const { return max_age_; }

 private:
  void push_locked(const drivers::SourceSample& sample, bool may_drop_stale);
  void drop_stale_locked();

  mutable std::mutex mutex_;
  std::condition_variable not_empty_;
  std::condition_variable not_full_;
  std::vector<drivers::SourceSample> ring_;
  std::vector<std::uint8_t> may_drop_stale_;  // per slot: pushed with push() (not push_wait)
  std::chrono::nanoseconds max_age_;
  std::size_t head_ = 0;  // index of the oldest sample
  std::size_t count_ = 0;
  std::uint64_t pushed_ = 0;
  std::uint64_t dropped_ = 0;
  std::uint64_t dropped_stale_ = 0;
};

}  // namespace bodyd::daemon
