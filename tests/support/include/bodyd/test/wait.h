// Waiting for an event with a timeout: behaviour, not timing. A test may wait generously for
// something to happen; how fast it happens is measured by the benchmarks, never asserted in a test.
#pragma once

#include <chrono>
#include <functional>
#include <future>
#include <thread>

namespace bodyd::test {

// Polls `done` every 5 ms for up to `timeout`; true as soon as it holds.
inline bool eventually(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return done();
}

// Runs `call` on another thread; true when it returned within `timeout`. Either way it has
// returned when this does (a call that never returns hangs the test, which then fails on the
// test's timeout), so `call` may use the caller's objects.
inline bool returns_within(const std::function<void()>& call, std::chrono::milliseconds timeout) {
  std::future<void> done = std::async(std::launch::async, call);
  const bool in_time = done.wait_for(timeout) == std::future_status::ready;
  done.get();
  return in_time;
}

}  // namespace bodyd::test
