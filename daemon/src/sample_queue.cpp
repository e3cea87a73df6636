#include "bodyd/daemon/sample_queue.h"

#include <stdexcept>

namespace bodyd::daemon {

SampleQueue::SampleQueue(std::size_t capacity) : ring_(capacity) {
  if (capacity == 0) throw std::invalid_argument("SampleQueue: capacity must be > 0");
}

void SampleQueue::push_locked(const drivers::SourceSample& sample) {
  if (count_ == ring_.size()) {  // full: drop the oldest
    head_ = (head_ + 1) % ring_.size();
    --count_;
    ++dropped_;
  }
  ring_[(head_ + count_) % ring_.size()] = sample;
  ++count_;
  ++pushed_;
}

void SampleQueue::push(const drivers::SourceSample& sample) {
  {
    std::lock_guard lock(mutex_);
    push_locked(sample);
  }
  not_empty_.notify_one();
}

bool SampleQueue::push_wait(const drivers::SourceSample& sample, std::chrono::nanoseconds timeout) {
  {
    std::unique_lock lock(mutex_);
    if (!not_full_.wait_for(lock, timeout, [this] { return count_ < ring_.size(); })) return false;
    push_locked(sample);
  }
  not_empty_.notify_one();
  return true;
}

bool SampleQueue::pop(drivers::SourceSample& out, std::chrono::nanoseconds timeout) {
  {
    std::unique_lock lock(mutex_);
    if (!not_empty_.wait_for(lock, timeout, [this] { return count_ > 0; })) return false;
    out = ring_[head_];
    head_ = (head_ + 1) % ring_.size();
    --count_;
  }
  not_full_.notify_one();
  return true;
}

std::size_t SampleQueue::size() const {
  std::lock_guard lock(mutex_);
  return count_;
}

std::uint64_t SampleQueue::pushed() const {
  std::lock_guard lock(mutex_);
  return pushed_;
}

std::uint64_t SampleQueue::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

}  // namespace bodyd::daemon
