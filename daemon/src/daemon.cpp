#include "bodyd/daemon/daemon.h"

#include "bodyd/daemon/control.h"
#include "bodyd/daemon/endpoint.h"
#include "bodyd/daemon/sample_queue.h"
#include "bodyd/drivers/open_source.h"
#include "bodyd/protocol/pose_message.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <zmq.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <fstream>
#include <mutex>
#include <optional>
#include <thread>

namespace bodyd::daemon {

using drivers::monotonic_ns;
using nlohmann::json;

ModelChoice choose_model(const DaemonConfig& config, std::string& warning) {
  ModelChoice choice{config.method, config.model_path.empty() ? default_model_path() : std::filesystem::path(config.model_path)};
  std::error_code ec;
  if (config.method == "diffusion" && config.model_path.empty() && !std::filesystem::exists(choice.model_path, ec)) {
    warning = "the default model " + choice.model_path.string() +
              " does not exist yet: using the ik baseline instead (train one with the trainer, docs/model.md, "
              "or pass --model FILE; --method ik silences this warning)";
    choice.method = "ik";
  }
  return choice;
}

namespace {

constexpr auto kPopTimeout = std::chrono::milliseconds(20);
constexpr std::int64_t kSkeletonPeriodNs = 1'000'000'000;  // docs/protocol.md: once per second

// The last N durations, written by one thread, read (approximately) by others.
class TimingRing {
 public:
  static constexpr std::size_t kSize = 4096;
  void add(std::int64_t value_ns) {
    const std::uint64_t i = count_.load(std::memory_order_relaxed);
    values_[i % kSize].store(value_ns, std::memory_order_relaxed);
    count_.store(i + 1, std::memory_order_release);
  }
  // {count, p50, p99, max} in microseconds over the retained values.
  json summary_us() const {
    const std::uint64_t n = count_.load(std::memory_order_acquire);
    const std::size_t m = static_cast<std::size_t>(std::min<std::uint64_t>(n, kSize));
    if (m == 0) return json{{"count", 0}};
    std::vector<std::int64_t> v(m);
    for (std::size_t i = 0; i < m; ++i) v[i] = values_[i].load(std::memory_order_relaxed);
    std::sort(v.begin(), v.end());
    auto pct = [&](double p) {
      const std::size_t k = std::min(m - 1, static_cast<std::size_t>(std::ceil(p * static_cast<double>(m))) - (p > 0 ? 1 : 0));
      return static_cast<double>(v[k]) / 1000.0;
    };
    return json{{"count", n}, {"window", m}, {"p50", pct(0.5)}, {"p99", pct(0.99)}, {"max", static_cast<double>(v.back()) / 1000.0}};
  }

 private:
  std::array<std::atomic<std::int64_t>, kSize> values_{};
  std::atomic<std::uint64_t> count_{0};
};

// The protocol's skeleton message of a reconstruction skeleton.
protocol::SkeletonMessage skeleton_message(const Skeleton& skeleton) {
  protocol::SkeletonMessage m;
  for (int j = 0; j < skeleton.size(); ++j) {
    m.names.push_back(skeleton.names[j]);
    m.parents.push_back(static_cast<std::int16_t>(skeleton.parents[j]));
    const Vec3& o = skeleton.offsets[j];
    m.offsets_m.push_back({static_cast<float>(o.x()), static_cast<float>(o.y()), static_cast<float>(o.z())});
  }
  m.skeleton_id = protocol::skeleton_id_of(m);
  return m;
}

std::string zmq_error_text() { return zmq_strerror(zmq_errno()); }

}  // namespace

struct Daemon::Impl final : ControlTarget {
  DaemonConfig config;
  ReconstructorFactory factory;
  std::function<void(const FrameTiming&)> observer;

  void* context = nullptr;
  void* pub = nullptr;
  void* rep = nullptr;
  std::string pub_bound, control_bound, curve_public;

  SampleQueue queue;
  std::vector<std::unique_ptr<drivers::TrackerSource>> sources;
  std::unique_ptr<Reconstructor> recon;  // the reconstruction thread's, once started
  std::thread recon_thread, control_thread;
  bool started = false;
  std::int64_t start_ns = 0;

  std::atomic<bool> stop_flag{false};
  std::atomic<bool> shutdown_requested{false};
  std::atomic<bool> fatal{false};
  std::atomic<bool> drained{false};
  std::atomic<bool> sources_started{false};
  std::mutex wake_mutex;
  std::condition_variable wake;

  // Statistics (written by the reconstruction thread).
  std::atomic<std::uint64_t> samples_in{0}, frames_out{0}, sends_failed{0}, not_ready{0}, encode_failed{0},
      skipped_by_rate{0}, subscriptions{0};
  std::array<std::atomic<std::uint64_t>, kRoleCount> role_samples{};
  TimingRing reconstruct_ring, latency_ring;
  std::atomic<double> last_head_y_m{0.0};
  std::atomic<std::int64_t> last_head_arrival_ns{0};

  // State shared with the control thread.
  mutable std::mutex shared_mutex;
  protocol::SkeletonMessage skeleton_msg;
  std::string method_name, model_path_text;
  double head_height_m = 0.0;
  bool height_calibrated = false;
  bool offsets_configured = false;

  // Commands from the control thread to the reconstruction thread.
  struct Command {
    enum class Kind { Height, FromHead, Swap } kind = Kind::Height;
    double height_m = 0.0;
    std::unique_ptr<Reconstructor> recon;
    std::string model_path;
  };
  std::mutex command_mutex;
  std::condition_variable command_done_cv;
  std::optional<Command> pending_command;
  std::atomic<bool> command_waiting{false};
  bool command_done = false;
  json command_result;

  // Reconstruction-thread state.
  std::uint64_t seq = 0;
  std::int64_t last_pose_t_ns = INT64_MIN;
  std::int64_t next_due_ns = INT64_MIN;
  BodyPose body;
  protocol::PoseMessage pose_msg;
  std::vector<std::uint8_t> pose_bytes, skeleton_bytes;
  int hips_index = -1;
  std::int64_t last_skeleton_pub_ns = 0;
  bool head_seen = false;
  std::int64_t next_no_head_warning_ns = 0;

  Impl(DaemonConfig c, ReconstructorFactory f)
      : config(std::move(c)), factory(std::move(f)), queue(std::max<std::size_t>(config.queue_capacity, 16)) {
    for (const auto& o : config.offsets) offsets_configured |= o.has_value();
  }

  // ---------------------------------------------------------------- sockets
  std::string bind_socket(void* socket, const std::string& endpoint, const char* what, std::string& bound) {
    if (std::string e = check_bind_endpoint(endpoint, config.allow_remote, what); !e.empty()) return e;
    if (std::string e = prepare_ipc_endpoint(endpoint, what); !e.empty()) return e;
    if (zmq_bind(socket, endpoint.c_str()) != 0) {
      const int err = zmq_errno();
      if (err == EADDRINUSE)
        return std::string(what) + " " + endpoint + ": address in use (another bodyd running? stop it, or choose another " +
               what + " endpoint)";
      return std::string(what) + " " + endpoint + ": cannot bind: " + zmq_strerror(err) +
             (err == EINVAL || err == EPROTONOSUPPORT ? " (write ipc:///PATH or tcp://127.0.0.1:PORT)" : "");
    }
    char last[512] = {};
    size_t size = sizeof(last);
    if (zmq_getsockopt(socket, ZMQ_LAST_ENDPOINT, last, &size) == 0) bound = last;
    else bound = endpoint;
    if (!is_local_endpoint(endpoint)) {
      if (curve_public.empty())
        spdlog::warn("{} {}: bound to a non-loopback address WITHOUT encryption: anyone on the network can {}. "
                     "Configure CURVE (bodyd --gen-keys DIR; --curve-secret-key DIR/server.secret)",
                     what, endpoint, std::string(what) == "--pub" ? "watch this body's motion" : "control bodyd");
      else
        spdlog::info("{} {}: reachable from other machines; CURVE encryption is on", what, endpoint);
    }
    return {};
  }

  std::string set_curve(void* socket) {
    if (config.curve_secret_key_file.empty()) return {};
    std::string secret;
    if (std::string e = read_curve_key_file(config.curve_secret_key_file, secret); !e.empty()) return e;
    const int one = 1;
    if (zmq_setsockopt(socket, ZMQ_CURVE_SERVER, &one, sizeof(one)) != 0 ||
        zmq_setsockopt(socket, ZMQ_CURVE_SECRETKEY, secret.c_str(), 40) != 0)
      return "CURVE: " + zmq_error_text() + " (is libzmq built with CURVE?)";
    curve_public = curve_public_from_secret(secret);
    return {};
  }

  std::string open_sockets() {
    context = zmq_ctx_new();
    if (!context) return "zmq_ctx_new: " + zmq_error_text();
    pub = zmq_socket(context, ZMQ_XPUB);
    if (!pub) return "zmq_socket(XPUB): " + zmq_error_text();
    const int hwm = config.send_hwm, verboser = 1, linger_ms = 500;
    zmq_setsockopt(pub, ZMQ_SNDHWM, &hwm, sizeof(hwm));
    // Every subscribe and unsubscribe reaches us: subscriber counting, --wait-for-subscriber,
    // and the skeleton sent to each new subscriber.
    zmq_setsockopt(pub, ZMQ_XPUB_VERBOSER, &verboser, sizeof(verboser));
    zmq_setsockopt(pub, ZMQ_LINGER, &linger_ms, sizeof(linger_ms));
    if (std::string e = set_curve(pub); !e.empty()) return e;
    if (std::string e = bind_socket(pub, config.pub_endpoint, "--pub", pub_bound); !e.empty()) return e;

    if (!config.control_endpoint.empty() && config.control_endpoint != "none") {
      rep = zmq_socket(context, ZMQ_REP);
      if (!rep) return "zmq_socket(REP): " + zmq_error_text();
      const std::int64_t max_request = 64 * 1024;  // a request is a few bytes; refuse floods
      const int zero = 0;
      zmq_setsockopt(rep, ZMQ_MAXMSGSIZE, &max_request, sizeof(max_request));
      zmq_setsockopt(rep, ZMQ_LINGER, &zero, sizeof(zero));
      if (std::string e = set_curve(rep); !e.empty()) return e;
      if (std::string e = bind_socket(rep, config.control_endpoint, "--control", control_bound); !e.empty()) return e;
    }
    return {};
  }

  void close_sockets() {
    if (pub) zmq_close(pub);
    if (rep) zmq_close(rep);
    pub = rep = nullptr;
    if (context) zmq_ctx_term(context);
    context = nullptr;
  }

  // ---------------------------------------------------------------- skeleton
  // Reconstruction thread (or start()): refreshes the shared skeleton message from `recon`.
  void refresh_skeleton() {
    protocol::SkeletonMessage m = skeleton_message(recon->skeleton());
    hips_index = recon->skeleton().find("Hips");
    std::lock_guard lock(shared_mutex);
    skeleton_msg = std::move(m);
    method_name = std::string(recon->name());
    head_height_m = recon->user_height();
    if (auto s = protocol::encode_skeleton(skeleton_msg, skeleton_bytes); !s.ok())
      spdlog::error("the reconstructor's skeleton cannot be encoded: {} (a bug: please report it)", s.error);
  }

  void publish_skeleton() {
    std::vector<std::uint8_t> bytes;
    {
      std::lock_guard lock(shared_mutex);
      bytes = skeleton_bytes;
    }
    if (bytes.empty()) return;
    const auto topic = protocol::kSkeletonTopic;
    if (zmq_send(pub, topic.data(), topic.size(), ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
        zmq_send(pub, bytes.data(), bytes.size(), ZMQ_DONTWAIT) < 0)
      sends_failed.fetch_add(1, std::memory_order_relaxed);
    last_skeleton_pub_ns = monotonic_ns();
  }

  // Reads subscription messages from the XPUB socket without blocking. True if one arrived.
  bool read_subscriptions() {
    bool any = false;
    std::array<char, 256> buffer{};
    for (;;) {
      const int n = zmq_recv(pub, buffer.data(), buffer.size(), ZMQ_DONTWAIT);
      if (n < 1) break;
      any = true;
      const std::string_view topic(buffer.data() + 1, std::min<std::size_t>(static_cast<std::size_t>(n), buffer.size()) - 1);
      if (buffer[0] == 1) {
        subscriptions.fetch_add(1, std::memory_order_relaxed);
        spdlog::debug("new subscription \"{}\"", topic);
        // Whoever subscribes to the skeleton topic gets it at once (otherwise within a second).
        if (protocol::kSkeletonTopic.substr(0, topic.size()) == topic) publish_skeleton();
      } else if (buffer[0] == 0 && subscriptions.load(std::memory_order_relaxed) > 0) {
        subscriptions.fetch_sub(1, std::memory_order_relaxed);
      }
    }
    return any;
  }

  // ---------------------------------------------------------------- reconstruction thread
  void apply_offset(TrackerSample& s) const {
    const auto& o = config.offsets[static_cast<int>(s.role)];
    if (!o || !s.valid) return;
    s.position_m = s.position_m + s.rotation * o->position_m;
    s.rotation = (s.rotation * o->rotation).normalized();
  }

  // The output-rate gate: with rate_hz > 0, a head sample yields a pose only if its time has
  // reached the next due time (a quarter period early is fine: jitter must not halve the rate).
  bool due(std::int64_t t_ns) {
    if (config.rate_hz <= 0.0) return true;
    const auto period_ns = static_cast<std::int64_t>(1e9 / config.rate_hz);
    if (next_due_ns != INT64_MIN && t_ns + period_ns / 4 < next_due_ns) return false;
    next_due_ns = (next_due_ns == INT64_MIN || t_ns - next_due_ns > period_ns) ? t_ns + period_ns : next_due_ns + period_ns;
    return true;
  }

  void fill_pose_message(std::int64_t t_ns) {
    const GlobalPose& g = body.global;
    const std::size_t n = g.positions.size();
    pose_msg.joints.resize(n);
    for (std::size_t j = 0; j < n; ++j) {
      const Vec3& p = g.positions[j];
      const Quat q = g.rotations[j].normalized();
      pose_msg.joints[j].position_m = {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())};
      pose_msg.joints[j].rotation_xyzw = {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                                          static_cast<float>(q.w())};
    }
    pose_msg.seq = seq;
    pose_msg.t_ns = t_ns;
    std::uint32_t flags = 0;
    if (body.tracker_valid[0]) flags |= protocol::kFlagHeadValid;
    if (body.tracker_valid[1]) flags |= protocol::kFlagLeftHandValid;
    if (body.tracker_valid[2]) flags |= protocol::kFlagRightHandValid;
    {
      std::lock_guard lock(shared_mutex);
      if (height_calibrated) flags |= protocol::kFlagHeightCalibrated;
      pose_msg.skeleton_id = skeleton_msg.skeleton_id;
    }
    if (offsets_configured) flags |= protocol::kFlagOffsetsCalibrated;
    pose_msg.flags = flags;
    pose_msg.foot_contact = static_cast<std::uint8_t>((body.foot_contact[0] ? protocol::kFootContactLeft : 0) |
                                                      (body.foot_contact[1] ? protocol::kFootContactRight : 0));
    if (hips_index >= 0 && static_cast<std::size_t>(hips_index) < n) {
      pose_msg.root_joint = static_cast<std::uint16_t>(hips_index);
      pose_msg.root_position_m = pose_msg.joints[hips_index].position_m;
      pose_msg.root_heading_rad = protocol::heading_rad_from_rotation(pose_msg.joints[hips_index].rotation_xyzw);
    } else {
      pose_msg.root_joint = protocol::kNoRootJoint;
    }
  }

  void handle_sample(drivers::SourceSample& in) {
    TrackerSample& s = in.sample;
    apply_offset(s);
    recon->push(s);
    samples_in.fetch_add(1, std::memory_order_relaxed);
    role_samples[static_cast<int>(s.role)].fetch_add(1, std::memory_order_relaxed);
    if (s.role != Role::Head) return;
    if (!head_seen) {
      head_seen = true;
      spdlog::info("first head sample received; publishing poses");
    }
    if (s.valid) {
      last_head_y_m.store(s.position_m.y(), std::memory_order_relaxed);
      last_head_arrival_ns.store(in.arrival_ns, std::memory_order_relaxed);
    }
    if (s.t_ns <= last_pose_t_ns) return;  // a pose for this time was already sent
    if (!due(s.t_ns)) {
      skipped_by_rate.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    FrameTiming timing;
    timing.arrival_ns = in.arrival_ns;
    timing.t_ns = s.t_ns;
    timing.reconstruct_start_ns = monotonic_ns();
    const bool ok = recon->reconstruct(s.t_ns, body);
    timing.reconstruct_end_ns = monotonic_ns();
    if (!ok) {
      not_ready.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    last_pose_t_ns = s.t_ns;
    reconstruct_ring.add(timing.reconstruct_end_ns - timing.reconstruct_start_ns);
    fill_pose_message(s.t_ns);
    pose_msg.publish_t_ns = monotonic_ns();
    if (auto st = protocol::encode_pose(pose_msg, pose_bytes); !st.ok()) {
      if (encode_failed.fetch_add(1, std::memory_order_relaxed) < 5)
        spdlog::error("pose at t_ns={} cannot be encoded: {} (a reconstructor bug; the pose is skipped)", s.t_ns, st.error);
      return;
    }
    const auto topic = protocol::kPoseTopic;
    // Never blocks: PUB drops for a subscriber whose queue (send_hwm) is full.
    timing.sent = zmq_send(pub, topic.data(), topic.size(), ZMQ_SNDMORE | ZMQ_DONTWAIT) >= 0 &&
                  zmq_send(pub, pose_bytes.data(), pose_bytes.size(), ZMQ_DONTWAIT) >= 0;
    timing.published_ns = monotonic_ns();
    timing.seq = seq++;
    if (timing.sent) frames_out.fetch_add(1, std::memory_order_relaxed);
    else sends_failed.fetch_add(1, std::memory_order_relaxed);
    latency_ring.add(timing.published_ns - timing.arrival_ns);
    if (observer) observer(timing);
  }

  json apply_command(Command& c) {
    switch (c.kind) {
      case Command::Kind::Height: {
        recon->set_user_height(c.height_m);
        {
          std::lock_guard lock(shared_mutex);
          height_calibrated = c.height_m > 0.0;
        }
        refresh_skeleton();
        spdlog::info("calibrated: standing head height {:.3f} m", recon->user_height());
        break;
      }
      case Command::Kind::FromHead: {
        const std::int64_t arrival_ns = last_head_arrival_ns.load();
        if (arrival_ns == 0 || monotonic_ns() - arrival_ns > 2'000'000'000)
          return control_error("no valid head sample in the last 2 s: wear the headset, stand up straight, and retry");
        // The reconstructors scale by the standing head height: the Head joint's height now.
        const double measured_m = last_head_y_m.load();
        if (!(measured_m >= kMinUserHeightM && measured_m <= kMaxUserHeightM))
          return control_error("the head is at y = " + std::to_string(measured_m) +
                               " m, not a plausible standing head height: stand up straight on the floor (y = 0) and retry");
        recon->set_user_height(measured_m);
        {
          std::lock_guard lock(shared_mutex);
          height_calibrated = true;
        }
        refresh_skeleton();
        spdlog::info("calibrated from the standing head height: {:.3f} m", recon->user_height());
        break;
      }
      case Command::Kind::Swap: {
        bool calibrated;
        {
          std::lock_guard lock(shared_mutex);
          calibrated = height_calibrated;
          model_path_text = c.model_path;
        }
        if (calibrated) c.recon->set_user_height(recon->user_height());
        recon = std::move(c.recon);
        last_pose_t_ns = INT64_MIN;
        refresh_skeleton();
        spdlog::info("model reloaded: {} ({})", recon->name(), c.model_path);
        break;
      }
    }
    publish_skeleton();
    std::lock_guard lock(shared_mutex);
    return json{{"ok", true},
                {"method", method_name},
                {"head_height_m", head_height_m},
                {"user_height_m", head_height_m / kHeadHeightPerStature},
                {"height_calibrated", height_calibrated},
                {"skeleton_id", skeleton_msg.skeleton_id}};
  }

  void process_command() {
    if (!command_waiting.load(std::memory_order_acquire)) return;
    std::optional<Command> c;
    {
      std::lock_guard lock(command_mutex);
      c = std::move(pending_command);
      pending_command.reset();
      command_waiting.store(false);
    }
    if (!c) return;
    json result = apply_command(*c);
    {
      std::lock_guard lock(command_mutex);
      command_result = std::move(result);
      command_done = true;
    }
    command_done_cv.notify_all();
  }

  bool start_sources() {
    for (std::size_t i = 0; i < sources.size(); ++i) {
      if (std::string e = sources[i]->start(queue, static_cast<std::uint16_t>(i)); !e.empty()) {
        spdlog::critical("{}", e);
        return false;
      }
    }
    sources_started.store(true);
    return true;
  }

  bool all_sources_finished() const {
    for (const auto& s : sources)
      if (!s->status().finished) return false;
    return true;
  }

  std::string source_names() const {
    std::string names;
    for (const auto& s : sources) names += (names.empty() ? "" : ", ") + s->name();
    return names;
  }

  void warn_if_no_head(std::int64_t now_ns) {
    if (head_seen || now_ns < next_no_head_warning_ns) return;
    if (next_no_head_warning_ns != 0)
      spdlog::warn("no trackers: waiting for a head sample from {} (is the headset on and tracking? "
                   "check the source with `bodyd --source ... --log-level debug`)",
                   source_names());
    next_no_head_warning_ns = now_ns + (next_no_head_warning_ns == 0 ? 3'000'000'000LL : 30'000'000'000LL);
  }

  void reconstruction_loop() {
    if (config.wait_for_subscriber) {
      spdlog::info("waiting for a subscriber on {} before starting the sources", pub_bound);
      while (!stop_flag.load()) {
        process_command();
        zmq_pollitem_t item{pub, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&item, 1, 50) > 0 && read_subscriptions()) break;
      }
      if (stop_flag.load()) return;
    }
    publish_skeleton();
    if (!start_sources()) {
      fatal.store(true);
      notify();
      return;
    }
    next_no_head_warning_ns = 0;
    drivers::SourceSample sample;
    while (!stop_flag.load(std::memory_order_relaxed)) {
      read_subscriptions();
      process_command();
      if (queue.pop(sample, kPopTimeout)) {
        handle_sample(sample);
      } else if (!drained.load() && all_sources_finished() && queue.size() == 0) {
        drained.store(true);
        spdlog::info("every source has finished; {} poses published", seq);
        notify();
      }
      const std::int64_t now = monotonic_ns();
      if (now - last_skeleton_pub_ns >= kSkeletonPeriodNs) publish_skeleton();
      warn_if_no_head(now);
    }
  }

  void control_loop() {
    while (!stop_flag.load()) {
      zmq_pollitem_t item{rep, 0, ZMQ_POLLIN, 0};
      if (zmq_poll(&item, 1, 100) <= 0) continue;
      zmq_msg_t msg;
      zmq_msg_init(&msg);
      const int n = zmq_msg_recv(&msg, rep, ZMQ_DONTWAIT);
      if (n < 0) {
        zmq_msg_close(&msg);
        continue;
      }
      std::string request(static_cast<const char*>(zmq_msg_data(&msg)), zmq_msg_size(&msg));
      // Drain further frames of a multipart request; only a single frame is a valid request.
      bool multipart = false;
      while (zmq_msg_more(&msg)) {
        multipart = true;
        zmq_msg_close(&msg);
        zmq_msg_init(&msg);
        if (zmq_msg_recv(&msg, rep, 0) < 0) break;
      }
      zmq_msg_close(&msg);
      const json reply = multipart ? control_error("a request is one frame of JSON text")
                                   : handle_control_request(request, *this);
      const std::string text = reply.dump(-1, ' ', false, json::error_handler_t::replace);
      if (zmq_send(rep, text.data(), text.size(), 0) < 0)
        spdlog::warn("control: cannot send the reply: {}", zmq_error_text());
    }
  }

  void notify() {
    std::lock_guard lock(wake_mutex);
    wake.notify_all();
  }

  // ---------------------------------------------------------------- ControlTarget (control thread)
  json run_command(Command c) {
    {
      std::unique_lock lock(command_mutex);
      pending_command = std::move(c);
      command_done = false;
      command_waiting.store(true, std::memory_order_release);
      if (command_done_cv.wait_for(lock, std::chrono::seconds(5), [this] { return command_done; }))
        return std::move(command_result);
      if (pending_command) {
        pending_command.reset();
        command_waiting.store(false);
        return control_error("the reconstruction thread did not take the command within 5 s");
      }
      command_done_cv.wait(lock, [this] { return command_done; });
      return std::move(command_result);
    }
  }

  json status() override {
    json j = json::object();
    j["ok"] = true;
    j["uptime_s"] = static_cast<double>(monotonic_ns() - start_ns) / 1e9;
    {
      std::lock_guard lock(shared_mutex);
      j["method"] = method_name;
      j["model"] = model_path_text;
      j["head_height_m"] = head_height_m;
      j["user_height_m"] = head_height_m / kHeadHeightPerStature;
      j["height_calibrated"] = height_calibrated;
      j["skeleton_id"] = skeleton_msg.skeleton_id;
    }
    j["offsets_configured"] = offsets_configured;
    json src = json::array();
    for (const auto& s : sources) {
      const drivers::SourceStatus st = s->status();
      src.push_back({{"name", st.name},
                     {"connected", st.connected},
                     {"finished", st.finished},
                     {"samples", st.samples},
                     {"rate_hz", st.rate_hz},
                     {"last_error", st.last_error}});
    }
    j["sources"] = src;
    j["sources_started"] = sources_started.load();
    j["samples_in"] = samples_in.load();
    j["samples_by_role"] = {{"head", role_samples[0].load()},
                            {"left_hand", role_samples[1].load()},
                            {"right_hand", role_samples[2].load()}};
    j["samples_dropped"] = queue.dropped();
    j["queue_depth"] = queue.size();
    j["queue_capacity"] = queue.capacity();
    j["frames_out"] = frames_out.load();
    j["frames_not_ready"] = not_ready.load();
    j["frames_skipped_by_rate"] = skipped_by_rate.load();
    j["sends_failed"] = sends_failed.load();
    j["encode_failed"] = encode_failed.load();
    j["reconstruct_us"] = reconstruct_ring.summary_us();
    j["latency_us"] = latency_ring.summary_us();
    j["subscriptions"] = subscriptions.load();
    j["pub"] = pub_bound;
    j["control"] = control_bound;
    j["curve"] = !curve_public.empty();
    j["rate_hz"] = config.rate_hz;
    return j;
  }

  json skeleton() override {
    std::lock_guard lock(shared_mutex);
    json offsets = json::array();
    for (const auto& o : skeleton_msg.offsets_m) offsets.push_back({o[0], o[1], o[2]});
    return json{{"ok", true},
                {"skeleton_id", skeleton_msg.skeleton_id},
                {"names", skeleton_msg.names},
                {"parents", skeleton_msg.parents},
                {"offsets_m", offsets},
                {"head_height_m", head_height_m}};
  }

  json calibrate_height(double height_m) override {
    Command c;
    c.kind = Command::Kind::Height;
    c.height_m = height_m;
    return run_command(std::move(c));
  }

  json calibrate_from_head() override {
    Command c;
    c.kind = Command::Kind::FromHead;
    return run_command(std::move(c));
  }

  json reload_model(const std::optional<std::string>& path) override {
    std::string method, current;
    {
      std::lock_guard lock(shared_mutex);
      current = model_path_text;
    }
    ModelChoice choice{config.method, path ? std::filesystem::path(*path)
                                           : (current.empty() ? default_model_path() : std::filesystem::path(current))};
    if (path) choice.method = "diffusion";  // a model file is for the diffusion method
    std::string error;
    std::unique_ptr<Reconstructor> next = factory(choice, error);
    if (!next) return control_error("reload-model: " + error);
    Command c;
    c.kind = Command::Kind::Swap;
    c.recon = std::move(next);
    c.model_path = choice.method == "ik" ? std::string() : choice.model_path.string();
    return run_command(std::move(c));
  }

  json shutdown() override {
    spdlog::info("shutdown requested on the control socket");
    shutdown_requested.store(true);
    notify();
    return json{{"ok", true}};
  }
};

Daemon::Daemon(DaemonConfig config, ReconstructorFactory factory)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(factory))) {}

Daemon::~Daemon() { stop(); }

void Daemon::set_frame_observer(std::function<void(const FrameTiming&)> observer) { impl_->observer = std::move(observer); }

std::string Daemon::start() {
  Impl& d = *impl_;
  if (d.started) return "bodyd: already started";
  d.start_ns = monotonic_ns();

  // The reconstructor.
  std::string warning;
  const ModelChoice choice = choose_model(d.config, warning);
  if (!warning.empty()) spdlog::warn("{}", warning);
  std::string error;
  d.recon = d.factory(choice, error);
  if (!d.recon) return error.empty() ? "cannot create the " + choice.method + " reconstructor" : error;
  if (const double head_height_m = configured_head_height_m(d.config); head_height_m > 0.0) {
    d.recon->set_user_height(head_height_m);
    d.height_calibrated = true;
  }
  d.model_path_text = choice.method == "ik" ? std::string() : choice.model_path.string();
  d.refresh_skeleton();
  spdlog::info("reconstruction: {}{}, standing head height {:.3f} m, skeleton {} joints (id {:#010x})", d.recon->name(),
               d.model_path_text.empty() ? "" : " (" + d.model_path_text + ")", d.recon->user_height(),
               d.recon->skeleton().size(), d.skeleton_msg.skeleton_id);

  // The sources.
  std::vector<std::string> specs = d.config.sources;
  drivers::SourceOptions options;
  options.replay.paced = !d.config.fast;
  options.replay.speed = d.config.replay_speed;
  options.replay.loop = d.config.loop;
  options.sim = d.config.sim;
  if (specs.empty()) {
    specs.push_back("replay:" + bundled_recording_path().string());
    options.replay.loop = !d.config.exit_at_end;
    spdlog::info("no --source given: replaying the bundled recording {}{}", bundled_recording_path().string(),
                 options.replay.loop ? " in a loop (Ctrl-C to stop)" : "");
  }
  for (const std::string& spec : specs) {
    auto source = drivers::open_source(spec, options, error);
    if (!source) return error;
    spdlog::info("source: {}", source->name());
    d.sources.push_back(std::move(source));
  }

  // The sockets.
  if (std::string e = d.open_sockets(); !e.empty()) {
    d.close_sockets();
    return e;
  }
  spdlog::info("publishing poses on {}{}", d.pub_bound, d.curve_public.empty() ? "" : " (CURVE)");
  if (d.rep) spdlog::info("control socket on {}", d.control_bound);
  if (!d.config.endpoints_file.empty()) {
    const std::filesystem::path path = d.config.endpoints_file;
    const std::filesystem::path tmp = path.string() + ".tmp";
    std::ofstream out(tmp);
    out << json{{"pub", d.pub_bound}, {"control", d.control_bound}, {"curve_public_key", d.curve_public}}.dump() << "\n";
    out.close();
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (!out || ec) {
      d.close_sockets();
      return d.config.endpoints_file + ": cannot write the endpoints file";
    }
  }

  d.started = true;
  d.recon_thread = std::thread([&d] {
    try {
      d.reconstruction_loop();
    } catch (const std::exception& e) {
      spdlog::critical("reconstruction thread stopped: {} (a bug: please report it with the log)", e.what());
      d.fatal.store(true);
      d.notify();
    }
  });
  if (d.rep) d.control_thread = std::thread([&d] {
    try {
      d.control_loop();
    } catch (const std::exception& e) {
      spdlog::error("control thread stopped: {} (the pose stream continues)", e.what());
    }
  });
  return {};
}

int Daemon::run(const volatile std::sig_atomic_t* signal_flag) {
  Impl& d = *impl_;
  if (!d.started) return 1;
  for (;;) {
    if (signal_flag && *signal_flag) {
      spdlog::info("signal received: shutting down");
      break;
    }
    if (d.stop_flag.load() || d.shutdown_requested.load()) break;
    if (d.fatal.load()) break;
    if (d.config.exit_at_end && d.drained.load()) break;
    std::unique_lock lock(d.wake_mutex);
    d.wake.wait_for(lock, std::chrono::milliseconds(50));
  }
  stop();
  return d.fatal.load() ? 1 : 0;
}

void Daemon::request_stop() {
  impl_->stop_flag.store(true);
  impl_->notify();
}

void Daemon::stop() {
  Impl& d = *impl_;
  d.stop_flag.store(true);
  d.notify();
  if (d.recon_thread.joinable()) d.recon_thread.join();
  for (auto& s : d.sources) s->stop();
  if (d.control_thread.joinable()) d.control_thread.join();
  if (d.started) spdlog::info("stopped: {} samples in, {} poses out, {} samples dropped", d.samples_in.load(),
                              d.frames_out.load(), d.queue.dropped());
  d.started = false;
  d.close_sockets();
}

const std::string& Daemon::pub_endpoint() const { return impl_->pub_bound; }
const std::string& Daemon::control_endpoint() const { return impl_->control_bound; }
const std::string& Daemon::curve_public_key() const { return impl_->curve_public; }
json Daemon::status() const { return impl_->status(); }

}  // namespace bodyd::daemon
