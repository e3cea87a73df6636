// A tracker-source sink that keeps every sample it is given. Header-only: a test that
// includes this links bodyd_io. (Log lines: log_capture.h.)
#pragma once

#include "bodyd/io/source.h"

#include <chrono>
#include <cstddef>
#include <mutex>
#include <thread>
#include <vector>

namespace bodyd::test {

// Every sample, in arrival order; push_wait never blocks.
class CollectingSink final : public drivers::SampleSink {
 public:
  void push(const drivers::SourceSample& s) override {
    std::lock_guard lock(mutex_);
    samples_.push_back(s);
  }
  bool push_wait(const drivers::SourceSample& s, std::chrono::nanoseconds) override {
    push(s);
    return true;
  }
  std::vector<drivers::SourceSample> samples() const {
    std::lock_guard lock(mutex_);
    return samples_;
  }
  std::size_t size() const {
    std::lock_guard lock(mutex_);
    return samples_.size();
  }
  // The samples once `n` have come (or after 2 s: fewer).
  std::vector<drivers::SourceSample> wait_for(std::size_t n) const {
    for (int i = 0; i < 200 && size() < n; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return samples();
  }

 private:
  mutable std::mutex mutex_;
  std::vector<drivers::SourceSample> samples_;
};

}  // namespace bodyd::test
