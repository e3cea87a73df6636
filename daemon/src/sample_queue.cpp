#include "bodyd/daemon/sample_queue.h"

#include "bodyd/base/require.h"

namespace bodyd::daemon {
namespace {

// A copy of `field`, read while holding `mutex`.
template <class T>
T read_locked(std::mutex& mutex, const T& field) {
  std::lock_guard lock(mutex);
  return field;
}

}  // namespace

SampleQueue::SampleQueue(std::size_t capacity, std::chrono::nanoseconds max_age)
    : ring_(capacity), may_drop_stale_(capacity, 0), max_age_(max_age) {
  // The Daemon clamps the user's queue_capacity and queue_max_age_ms to their checked ranges.
  BODYD_REQUIRE(capacity > 0, "SampleQueue: capacity must be > 0");
  BODYD_REQUIRE(max_age >= std::chrono::nanoseconds::zero(), "SampleQueue: max_age must be >= 0");
}

void SampleQueue::push_locked(const drivers::SourceSample& sample, bool may_drop_stale) {
  if (count_ == ring_.size()) {  // full: drop the oldest
    head_ = (head_ + 1) % ring_.size();
    --count_;
    ++dropped_;
  }
  const std::size_t slot = (head_ + count_) % ring_.size();
  ring_[slot] = sample;
  may_drop_stale_[slot] = may_drop_stale ? 1 : 0;
  ++count_;
  ++pushed_;
}

void SampleQueue::drop_stale_locked() {
  if (max_age_ <= std::chrono::nanoseconds::zero() || count_ < 2) return;
  const std::int64_t newest_ns = ring_[(head_ + count_ - 1) % ring_.size()].arrival_ns;
  const std::int64_t max_age_ns = max_age_.count();
  // The newest sample always stays: at least one sample is taken. Arrival times come from one
  // monotonic clock but from several source threads, so they may be slightly out of order; a
  // sample newer than the newest is never stale. (newest - oldest cannot overflow: both are
  // monotonic-clock readings.)
  while (count_ > 1 && may_drop_stale_[head_] && newest_ns - ring_[head_].arrival_ns > max_age_ns) {
    head_ = (head_ + 1) % ring_.size();
    --count_;
    ++dropped_stale_;
  }
}

void SampleQueue::push(const drivers::SourceSample& sample) {
  {
    std::lock_guard lock(mutex_);
    push_locked(sample, true);
  }
  not_empty_.notify_one();
}

bool SampleQueue::push_wait(const drivers::SourceSample& sample, std::chrono::nanoseconds timeout) {
  {
    std::unique_lock lock(mutex_);
    if (!not_full_.wait_for(lock, timeout, [this] { return count_ < ring_.size(); })) return false;
    push_locked(sample, false);
  }
  not_empty_.notify_one();
  return true;
}

bool SampleQueue::pop(drivers::SourceSample& out, std::chrono::nanoseconds timeout) {
  {
    std::unique_lock lock(mutex_);
    if (!not_empty_.wait_for(lock, timeout, [this] { return count_ > 0; })) return false;
    drop_stale_locked();
    out = ring_[head_];
    head_ = (head_ + 1) % ring_.size();
    --count_;
  }
  not_full_.notify_one();
  return true;
}

std::size_t SampleQueue::size() const { return read_locked(mutex_, count_); }
std::uint64_t SampleQueue::pushed() const { return read_locked(mutex_, pushed_); }
std::uint64_t SampleQueue::dropped() const { return read_locked(mutex_, dropped_); }
std::uint64_t SampleQueue::dropped_stale() const { return read_locked(mutex_, dropped_stale_); }

}  // namespace bodyd::daemon
