// How many poses per second the daemon publishes, from the pose stream's own numbers (issue 43
// item 16): `seq` counts every pose the daemon published (the ones lost on the way included) and
// `publish_t_ns` is the daemon's clock when it sent each one (docs/protocol.md). Neither the
// bridge's nor the browser's speed enters the figure: a bridge or a page that falls behind, or
// that receives poses in bursts, still reports what the daemon sent. What the page itself draws
// per second is the page's to count (viewer/viewer.js).
//
// Time is a parameter: the daemon's timestamps come in with each pose; the bridge calls clear()
// when the stream has gone quiet (its own clock, the only one that can tell).
#pragma once

#include <cstdint>
#include <deque>
#include <optional>

namespace bodyd::viewer {

class PublishRate {
 public:
  // The rate is taken over the poses published in the last `window_ns` of the daemon's clock.
  explicit PublishRate(std::int64_t window_ns = 1'000'000'000) : window_ns_(window_ns) {}

  // A pose received: its seq and publish_t_ns. A seq or a time that goes backwards means the
  // daemon restarted (a new count, a new clock): the window starts again from this pose.
  void add(std::uint64_t seq, std::int64_t publish_t_ns) {
    if (!poses_.empty() && (seq <= poses_.back().seq || publish_t_ns < poses_.back().publish_t_ns)) poses_.clear();
    poses_.push_back({seq, publish_t_ns});
    // Keep the newest pose at or before the window's start, so a full window is measured.
    while (poses_.size() > 2 && poses_[1].publish_t_ns <= publish_t_ns - window_ns_) poses_.pop_front();
  }

  // The stream stopped (no pose for a while) or the connection was lost: no rate until two
  // new poses have arrived.
  void clear() { poses_.clear(); }

  // Poses published per second of the daemon's clock over the window; nullopt until two poses
  // with different publish times have arrived since the last clear() or restart.
  [[nodiscard]] std::optional<double> per_s() const {
    if (poses_.size() < 2) return std::nullopt;
    const Pose& first = poses_.front();
    const Pose& last = poses_.back();
    if (last.publish_t_ns <= first.publish_t_ns) return std::nullopt;
    return static_cast<double>(last.seq - first.seq) * 1e9 / static_cast<double>(last.publish_t_ns - first.publish_t_ns);
  }

 private:
  struct Pose {
    std::uint64_t seq;
    std::int64_t publish_t_ns;
  };
  std::int64_t window_ns_;
  std::deque<Pose> poses_;
};

}  // namespace bodyd::viewer
