#include "bodyd/drivers/replay_source.h"

#include "bodyd/motion/tracker_log.h"

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
    return s;
  }

 private:
  // Span of the recording plus one sample period (the mean spacing of distinct timestamps).
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
    const std::int64_t period_ns =
        distinct > 1 ? (t_max - t_min) / (distinct - 1) : 11'111'111;  // 90 Hz when unknown
    return (t_max - t_min) + std::max<std::int64_t>(period_ns, 1);
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
    const std::int64_t host_start_ns = monotonic_ns();
    std::int64_t shift_ns = 0;
    SourceSample out;
    out.source_index = source_index;
    for (;;) {
      for (const TrackerSample& recorded : samples_) {
        out.sample = recorded;
        out.sample.t_ns = recorded.t_ns + shift_ns;
        if (options_.paced) {
          const double offset_ns = static_cast<double>(out.sample.t_ns - t_first) / options_.speed;
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
      shift_ns += loop_shift_ns_;
    }
    finished_.store(true);
  }

  std::string name_;
  std::vector<TrackerSample> samples_;
  ReplayOptions options_;
  std::int64_t loop_shift_ns_ = 0;

  std::thread thread_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_requested_ = false;
  std::atomic<bool> running_{false};
  std::atomic<bool> finished_{false};
  std::atomic<std::uint64_t> pushed_{0};
  RateMeter rate_;
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
  if (!std::filesystem::is_regular_file(log_path, ec)) {
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

}  // namespace bodyd::drivers
