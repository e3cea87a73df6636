// The bounded queue between the tracker sources and the reconstruction thread.
//
// Many producers (one thread per source), one consumer. Storage is allocated once, at
// construction; push never blocks: when the queue is full the oldest sample is dropped
// and counted (a live device must keep reading, and the newest sample matters most).
// push_wait lets a source that can wait (a file replayed as fast as possible) wait for room
// instead, so nothing is lost. A mutex + condition variable: the critical sections are a
// few copies, far below the reconstruction time, and the consumer sleeps while idle.
#pragma once

#include "bodyd/drivers/source.h"

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <vector>

namespace bodyd::daemon {

class SampleQueue final : public drivers::SampleSink {
 public:
  explicit SampleQueue(std::size_t capacity);

  void push(const drivers::SourceSample& sample) override;
  [[nodiscard]] bool push_wait(const drivers::SourceSample& sample, std::chrono::nanoseconds timeout) override;

  // Takes the oldest sample; waits up to `timeout` for one. False on timeout.
  [[nodiscard]] bool pop(drivers::SourceSample& out, std::chrono::nanoseconds timeout);

  [[nodiscard]] std::size_t size() const;
  [[nodiscard]] std::size_t capacity() const { return ring_.size(); }
  [[nodiscard]] std::uint64_t pushed() const;   // samples accepted (including later dropped ones)
  [[nodiscard]] std::uint64_t dropped() const;  // samples dropped because the queue was full

 private:
  void push_locked(const drivers::SourceSample& sample);

  mutable std::mutex mutex_;
  std::condition_variable not_empty_;
  std::condition_variable not_full_;
  std::vector<drivers::SourceSample> ring_;
  std::size_t head_ = 0;  // index of the oldest sample
  std::size_t count_ = 0;
  std::uint64_t pushed_ = 0;
  std::uint64_t dropped_ = 0;
};

}  // namespace bodyd::daemon
