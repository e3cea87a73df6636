// A SampleSink that keeps every sample it gets, for the source tests.
#pragma once

#include "bodyd/drivers/source.h"

#include <chrono>
#include <cstddef>
#include <mutex>
#include <vector>

namespace bodyd::test {

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

 private:
  mutable std::mutex mutex_;
  std::vector<drivers::SourceSample> samples_;
};

}  // namespace bodyd::test
