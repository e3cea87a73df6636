#include "bodyd/io/replay/replay_source.h"
#include "bodyd/io/open_source.h"

#include "bodyd/motion/limits.h"
#include "bodyd/motion/tracker_log.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <thread>

namespace bodyd::drivers {
namespace {

class ReplaySource final : public TrackerSource {
 public:
  ReplaySource(std::string name, std::vector<TrackerSample> samples, const ReplayOptions& options)
      : name_(std::move(name)), samples_(std::move(samples)), options_(options) {
    if (!(options_.speed > 0.0)) options_.speed = 1.0;
    if (!(options_.max_gap_s > 0.0)) options_.max_gap_s = ReplayOptions{}.max_gap_s;
    loop_shift_ns_ = compute_loop_shift();
  }
  ~ReplaySource() override { stop(); }

  const std::string& name() const override { return name_; }

  std::string start(SampleSink& sink, std::uint16_t source_index) override {
    if (thread_.joinable()) return name_ + ": already started";
    {
      std::lock_guard lock(mutex_);
      stop_requested_ = false;
    }
    running_.store(true);
    thread_ = std::thread([this, &sink, source_index] { run(sink, source_index); });
    return {};
  }

  void stop() override {
    {
      std::lock_guard lock(mutex_);
      stop_requested_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
    running_.store(false);
  }

  SourceStatus status() const override {
    SourceStatus s;
    s.name = name_;
    s.finished = finished_.load();
    s.connected = running_.load() && !s.finished;
    s.samples = pushed_.load(std::memory_order_relaxed);
    s.rate_hz = s.finished ? 0.0 : rate_.rate_hz();
    if (samples_.empty()) s.last_error = "the recording holds no samples";
    {
      std::lock_guard lock(mutex_);
      if (s.last_error.empty()) s.last_error = note_;
    }
    return s;
  }

 private:
  // Span of the recording plus one sample period (the mean spacing of distinct timestamps).
  // 0 when the span does not fit the time limits (the loop then restarts its time base).
  std::int64_t compute_loop_shift() const {
    if (samples_.empty()) return 0;
    std::int64_t t_min = samples_.front().t_ns, t_max = t_min;
    std::vector<std::int64_t> times;
    times.reserve(samples_.size());
    for (const auto& s : samples_) {
      t_min = std::min(t_min, s.t_ns);
      t_max = std::max(t_max, s.t_ns);
      times.push_back(s.t_ns);
    }
    std::sort(times.begin(), times.end());
    const auto distinct = std::unique(times.begin(), times.end()) - times.begin();
    std::int64_t span_ns = 0;
    if (__builtin_sub_overflow(t_max, t_min, &span_ns) || span_ns > limits::kMaxAbsTimeNs) return 0;
    const std::int64_t period_ns = distinct > 1 ? span_ns / (distinct - 1) : 11'111'111;  // 90 Hz when unknown
    return span_ns + std::max<std::int64_t>(period_ns, 1);
  }

  // Shifted time of a recorded sample; false when it would leave the time limits
  // (limits::kMaxAbsTimeNs), which a loop reaches after very many rounds or with a log near them.
  static bool shifted(std::int64_t t_ns, std::int64_t shift_ns, std::int64_t& out_t_ns) {
    return !__builtin_add_overflow(t_ns, shift_ns, &out_t_ns) && limits::time_plausible(out_t_ns);
  }

  void note(std::string text) {
    spdlog::warn("{}: {}", name_, text);
    std::lock_guard lock(mutex_);
    note_ = std::move(text);
  }

  // Waits until the host time `due_ns`; false when stop was requested first.
  bool wait_until(std::int64_t due_ns) {
    std::unique_lock lock(mutex_);
    const auto deadline = std::chrono::steady_clock::time_point(std::chrono::nanoseconds(due_ns));
    return !wake_.wait_until(lock, deadline, [this] { return stop_requested_; });
  }

  bool stop_requested() {
    std::lock_guard lock(mutex_);
    return stop_requested_;
  }

  void run(SampleSink& sink, std::uint16_t source_index) {
    if (samples_.empty()) {
      finished_.store(true);
      return;
    }
    const std::int64_t t_first = samples_.front().t_ns;
    std::int64_t host_start_ns = monotonic_ns();
    std::int64_t shift_ns = 0;
    // Paced: the log time that host_start_ns stands for. A jump forward by more than max_gap_s
    // moves it, so the replay waits max_gap_s (scaled by speed) instead of the whole jump.
    std::int64_t anchor_t_ns = t_first;
    std::int64_t previous_t_ns = t_first;
    const auto max_gap_ns = static_cast<std::int64_t>(options_.max_gap_s * 1e9);
    std::uint64_t jumps = 0;
    SourceSample out;
    out.source_index = source_index;
    for (;;) {
      for (const TrackerSample& recorded : samples_) {
        out.sample = recorded;
        if (!shifted(recorded.t_ns, shift_ns, out.sample.t_ns)) {
          // Looping further would overflow the time base (issue 11): start it over. Time goes
          // backwards once; the daemon starts the reconstruction over when it sees that.
          note("looped timestamps would pass the time limit (+-2^62 ns); the replay's time base starts over");
          shift_ns = 0;
          out.sample.t_ns = recorded.t_ns;
          anchor_t_ns = previous_t_ns = recorded.t_ns;
          host_start_ns = monotonic_ns();
        }
        if (options_.paced) {
          if (out.sample.t_ns - previous_t_ns > max_gap_ns) {
            // A jump in the log (a paused recording, a clock step): re-anchor rather than stall
            // silently for its whole length (issue 11). Documented in docs/tracker-log.md.
            ++jumps;
            const std::int64_t jump_ns = out.sample.t_ns - previous_t_ns;
            anchor_t_ns += jump_ns - max_gap_ns;
            note(fmt::format("the log's time jumps forward by {:.3f} s (jump {}); replayed as a {:.3f} s gap", jump_ns * 1e-9,
                             jumps, options_.max_gap_s));
          }
          previous_t_ns = out.sample.t_ns;
          const double offset_ns = static_cast<double>(out.sample.t_ns - anchor_t_ns) / options_.speed;
          const std::int64_t due_ns = host_start_ns + static_cast<std::int64_t>(offset_ns);
          if (!wait_until(due_ns)) return;
          if (options_.restamp) out.sample.t_ns = due_ns;
          out.arrival_ns = monotonic_ns();
          sink.push(out);
        } else {
          for (;;) {
            out.arrival_ns = monotonic_ns();
            if (sink.push_wait(out, std::chrono::milliseconds(50))) break;
            if (stop_requested()) return;
          }
          if ((pushed_.load(std::memory_order_relaxed) & 255) == 0 && stop_requested()) return;
        }
        pushed_.fetch_add(1, std::memory_order_relaxed);
        rate_.count(out.arrival_ns);
      }
      if (!options_.loop) break;
      if (loop_shift_ns_ == 0 || __builtin_add_overflow(shift_ns, loop_shift_ns_, &shift_ns)) shift_ns = limits::kMaxAbsTimeNs;
      if (options_.paced) previous_t_ns = t_first + shift_ns;  // a loop is not a jump
    }
    finished_.store(true);
  }

  std::string name_;
  std::vector<TrackerSample> samples_;
  ReplayOptions options_;
  std::int64_t loop_shift_ns_ = 0;

  std::thread thread_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_requested_ = false;
  std::atomic<bool> running_{false};
  std::atomic<bool> finished_{false};
  std::atomic<std::uint64_t> pushed_{0};
  RateMeter rate_;
  std::string note_;  // the last time-base event (jump, restart), shown as status().last_error; guarded by mutex_
};

}  // namespace

std::unique_ptr<TrackerSource> make_replay_source(std::string name, std::vector<TrackerSample> samples,
                                                  const ReplayOptions& options) {
  return std::make_unique<ReplaySource>(std::move(name), std::move(samples), options);
}

std::unique_ptr<TrackerSource> open_replay_source(const std::filesystem::path& log_path,
                                                  const ReplayOptions& options, std::string& error) {
  if (!(options.speed > 0.0)) {
    error = "replay speed must be > 0 (got " + std::to_string(options.speed) + ")";
    return nullptr;
  }
  std::error_code ec;
  const auto status = std::filesystem::status(log_path, ec);
  if (std::filesystem::is_directory(status)) {
    error = log_path.string() + ": is a directory; give a tracker log file (docs/tracker-log.md)";
    return nullptr;
  }
  if (std::filesystem::exists(status) && !std::filesystem::is_regular_file(status)) {
    error = log_path.string() + ": is not a regular file; give a tracker log file (docs/tracker-log.md)";
    return nullptr;
  }
  if (!std::filesystem::is_regular_file(status)) {
    error = log_path.string() + ": no such tracker log (make one from a BVH clip with bodyd-sim, "
                                "docs/tracker-log.md)";
    return nullptr;
  }
  try {
    TrackerLog log = read_tracker_log(log_path);
    if (log.samples.empty()) {
      error = log_path.string() + ": the tracker log holds no samples";
      return nullptr;
    }
    return make_replay_source("replay:" + log_path.string(), std::move(log.samples), options);
  } catch (const std::exception& e) {
    error = e.what();
    return nullptr;
  }
}

// The registry's factory (sources.cpp): replay:FILE.
std::unique_ptr<TrackerSource> open_replay_spec(const SourceSpec& spec, const SourceOptions& options,
                                                std::string& error) {
  return open_replay_source(spec.argument, options.replay, error);
}

}  // namespace bodyd::drivers
