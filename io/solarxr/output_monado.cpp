// `--output monado[:DIR][?trackers=...]`: bodyd as the SolarXR server of Monado's SolarXR driver
// on DIR/SlimeVRRpc (default $XDG_RUNTIME_DIR): bones and synthetic trackers in DataFeedUpdates
// (bodyd/io/solarxr/solarxr.h, docs/protocol-solarxr.md, docs/outputs.md "monado").
//
// One thread (drivers' FramedServer, bodyd/io/slimevr/framed_server.h) accepts and reads the
// clients' MessageBundles; this output answers a bundle's PollDataFeeds at once with one update
// of the latest pose (Monado waits at most 4 s for the first, before any pose may exist) and
// each SettingsRequest with the SteamVR tracker toggles. After a StartDataFeed the same thread
// sends DataFeedUpdates on bodyd's own clock, every minimum_time_since_last clamped to
// [kMinUpdateIntervalMs, kMaxUpdateIntervalMs], with the newest pose (or without bones before
// the first): Monado's feeder sends its headset and controllers only when an update arrives, so
// bodyd must not wait for a pose to send one. send() (the reconstruction thread) only keeps the
// newest pose.
#include "bodyd/base/log_rate.h"
#include "bodyd/io/output.h"
#include "bodyd/io/solarxr/solarxr.h"
#include "bodyd/io/slimevr/framed_server.h"
#include "bodyd/io/slimevr/slimevr_bridge.h"
#include "output_parts.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <map>
#include <mutex>

namespace bodyd::daemon {

namespace {

namespace sv = drivers::slimevr;
namespace sx = solarxr;

constexpr std::size_t kMaxRpcFrameBytes = 16 * 1024;   // Monado's requests are a few hundred bytes
constexpr std::size_t kMaxPendingBytes = 256 * 1024;   // about a second of updates
constexpr int kRpcSendBufferBytes = 64 * 1024;
constexpr std::uint32_t kMaxFramesPerSecond = 2000;
// The update interval bodyd keeps after a StartDataFeed: the request's minimum_time_since_last
// clamped to this range (Monado asks for 1 ms unless SOLARXR_SYNC_PERIOD_MS says otherwise; 10
// ms is bodyd's fastest pose rate through the bridge, drivers::slimevr::kMaxForwardHz).
constexpr std::int64_t kMinUpdateIntervalMs = 10;
constexpr std::int64_t kMaxUpdateIntervalMs = 1000;

// SolarXR's body parts of kBodyTrackers (output_parts.h), in its order; tracker i is number i + 1.
constexpr std::array<std::uint8_t, kBodyTrackers.size()> kBodyParts{sx::part::kHip,          sx::part::kLeftFoot,
                                                                    sx::part::kRightFoot,    sx::part::kChest,
                                                                    sx::part::kLeftLowerLeg, sx::part::kRightLowerLeg,
                                                                    sx::part::kLeftLowerArm, sx::part::kRightLowerArm};

class MonadoOutput final : public Output, sv::FramedHandler {
 public:
  MonadoOutput(std::string path, std::uint16_t mask)
      : path_(std::move(path)), mask_(mask), names_(place_names(kBodyTrackers, mask_)), server_(path_, kLimits, *this) {
    for (std::size_t i = 0; i < kBodyTrackers.size(); ++i) {
      if (!(mask_ & (1u << i))) continue;
      sx::SyntheticTracker t;
      t.tracker_num = static_cast<std::uint8_t>(i + 1);
      t.body_part = kBodyParts[i];
      t.display_name = "bodyd " + std::string(kBodyTrackers[i].name);
      latest_trackers_.push_back(t);
    }
    work_trackers_ = latest_trackers_;
    toggles_.waist = mask_ & 1;
    toggles_.left_foot = mask_ & 2;
    toggles_.right_foot = mask_ & 4;
    toggles_.chest = mask_ & 8;
    toggles_.left_knee = mask_ & 16;
    toggles_.right_knee = mask_ & 32;
    toggles_.left_elbow = mask_ & 64;
    toggles_.right_elbow = mask_ & 128;
    // Monado's driver enables a lower leg only with its knee and foot toggles, and a forearm
    // only with its elbow and hand toggles (solarxr_device.c): knees bring their feet, elbows
    // their hands (bodyd sends those bones in every update).
    toggles_.left_foot = toggles_.left_foot || toggles_.left_knee;
    toggles_.right_foot = toggles_.right_foot || toggles_.right_knee;
    toggles_.left_hand = toggles_.left_elbow;
    toggles_.right_hand = toggles_.right_elbow;
  }
  ~MonadoOutput() override { close(); }

  std::string name() const override { return "monado:" + path_; }

  std::string open() override {
    if (server_.running()) return {};
    if (std::string e = server_.start(); !e.empty()) return "--output " + name() + ": " + e;
    spdlog::info("monado: listening on {} (SolarXR)", path_);
    return {};
  }

  void set_skeleton(const Skeleton& skeleton, const std::vector<std::uint8_t>&) override {
    std::string error;
    if (!bones_.build(skeleton, error))
      spdlog::error("--output {}: {}; no bones are sent (the synthetic trackers are)", name(), error);
    std::string missing;  // -1 for them: those trackers are sent without a pose
    joints_ = place_joints(skeleton, kBodyTrackers, mask_, missing);
  }

  // WiVRn / Monado own the head: the body goes back into the space their samples came in.
  OutputSpace space() const override { return OutputSpace::Runtime; }

  bool send(const OutputFrame& frame, std::string& out_error) override {
    (void)out_error;
    const GlobalPose& g = frame.body.global;  // the runtime's space (space())
    for (std::size_t i = 0; i < joints_.size(); ++i) {
      const int j = joints_[i];
      sx::SyntheticTracker& st = work_trackers_[i];
      st.has_pose = j >= 0 && j < static_cast<int>(g.positions.size());
      if (!st.has_pose) continue;
      st.position_m = g.positions[static_cast<std::size_t>(j)];
      st.rotation = g.rotations[static_cast<std::size_t>(j)];
    }
    if (bones_.ready()) bones_.bones(g, work_bones_);
    std::lock_guard lock(server_.mutex());
    std::swap(latest_trackers_, work_trackers_);
    std::swap(latest_bones_, work_bones_);
    work_trackers_ = latest_trackers_;  // same size: no allocation
    ++poses_;
    if (server_.connections().empty()) ++updates_without_client_;
    return true;  // the server's thread sends it (tick)
  }

  nlohmann::json status() const override {
    std::lock_guard lock(server_.mutex());
    std::size_t streaming = 0;
    for (const auto& c : server_.connections()) streaming += static_cast<const Connection&>(*c).streaming ? 1 : 0;
    return {{"trackers", names_},
            {"socket", path_},
            {"clients", server_.connections().size()},
            {"streaming", streaming},
            {"connections", connections_total_},
            {"updates_sent", updates_sent_},
            {"updates_without_bones", updates_without_bones_},
            {"update_interval_ms", last_interval_ms_},
            {"polls_answered", polls_answered_},
            {"settings_answered", settings_answered_},
            {"updates_without_client", updates_without_client_},
            {"dropped", dropped_},
            {"rejected", rejected_},
            {"rejected_by_reason", rejected_by_reason_},
            {"bones", bones_.ready()}};
  }

  void close() override {
    if (server_.running()) server_.stop();
  }

 private:
  // The SolarXR RPC socket's limits (the socket loop is drivers' FramedServer).
  static constexpr sv::FramedServerLimits kLimits{kMaxRpcFrameBytes, sv::kMaxConnections, kMaxPendingBytes,
                                                  kRpcSendBufferBytes, kMaxFramesPerSecond, 8192};

  struct Connection final : sv::FramedConnection {
    bool streaming = false;
    std::int64_t interval_ns = 0;  // of the paced updates
    std::int64_t next_ns = 0;      // the next one is due
  };

  // The newest pose's update (or one without bones before the first) to `c`.
  void append_update(Connection& c, bool with_info) {
    append_frame(c, thread_encoder_.update(latest_trackers_, with_info, latest_bones_));
    if (latest_bones_.empty()) ++updates_without_bones_;
  }

  void reject(const std::string& reason, const std::string& detail) {
    ++rejected_;
    const std::uint64_t n = ++rejected_by_reason_[reason];
    if (log_occurrence(n))
      spdlog::warn("monado {}: {} ({}; {} so far, logged at the 1st, 2nd, 4th, 8th...)", path_, detail, reason, n);
  }

  static void append_frame(sv::FramedConnection& c, std::pair<const std::uint8_t*, std::size_t> bytes) {
    const auto framed = static_cast<std::uint32_t>(bytes.second + sv::kFrameHeaderBytes);
    const std::size_t at = c.out.size();
    c.out.resize(at + framed);
    for (int k = 0; k < 4; ++k) c.out[at + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>((framed >> (8 * k)) & 0xff);
    std::memcpy(c.out.data() + at + sv::kFrameHeaderBytes, bytes.first, bytes.second);
  }

  void handle(Connection& c, const sx::Request& r, std::int64_t arrival_ns) {
    if (r.stop_feed) c.streaming = false;
    if (r.start_feed) {
      const std::int64_t ms = std::clamp<std::int64_t>(r.min_interval_ms, kMinUpdateIntervalMs, kMaxUpdateIntervalMs);
      if (!c.streaming) c.next_ns = arrival_ns;  // the first at once
      c.streaming = true;
      c.interval_ns = ms * 1'000'000;
      last_interval_ms_ = ms;
    }
    if (r.polls > 0) {
      // One answer per bundle, however many polls it holds: a request's work is bounded by its
      // bytes. It names the trackers (Monado makes its generic trackers from it).
      append_update(c, true);
      polls_answered_ += static_cast<std::uint64_t>(r.polls);
    }
    for (std::uint32_t tx : r.settings_requests) {
      append_frame(c, thread_encoder_.settings_response(tx, toggles_));
      ++settings_answered_;
    }
    for (std::uint32_t tx : r.heartbeat_requests) append_frame(c, thread_encoder_.heartbeat_response(tx));
  }

  // ---- sv::FramedHandler (the server's thread, with its mutex held) ----

  std::unique_ptr<sv::FramedConnection> make_connection() override { return std::make_unique<Connection>(); }

  void accepted(sv::FramedConnection&) override {
    ++connections_total_;
    spdlog::info("monado {}: a client connected", path_);
  }

  void frame(sv::FramedConnection& c, const std::uint8_t* payload, std::size_t size, std::int64_t arrival_ns) override {
    // FlatBuffers' verifier wants the buffer aligned: copy the payload to the start of one.
    scratch_.assign(payload, payload + size);
    sx::Request r;
    std::string error;
    if (!sx::decode_request(scratch_.data(), scratch_.size(), r, error)) {
      reject("malformed", error);
      return;
    }
    handle(static_cast<Connection&>(c), r, arrival_ns);
  }

  int tick(std::int64_t now) override {
    std::int64_t wait_ns = 100'000'000;
    for (const auto& cp : server_.connections()) {
      auto& c = static_cast<Connection&>(*cp);
      if (c.drop || !c.streaming) continue;
      if (now >= c.next_ns) {
        append_update(c, false);
        ++updates_sent_;
        c.last_frame_ns = now;  // a client that takes a data feed is not idle (one that stops reading is dropped)
        // On the request's clock; one that fell far behind (a stalled thread) starts again now.
        c.next_ns += c.interval_ns;
        if (c.next_ns <= now) c.next_ns = now + c.interval_ns;
      }
      wait_ns = std::min(wait_ns, c.next_ns - now);
    }
    return static_cast<int>((wait_ns + 999'999) / 1'000'000);
  }

  void dropping(sv::FramedConnection*, sv::FramedDrop why, std::size_t bytes) override {
    switch (why) {
      case sv::FramedDrop::FrameTooLong:
      case sv::FramedDrop::FrameTooShort:
        reject(why == sv::FramedDrop::FrameTooLong ? "frame_too_long" : "frame_too_short",
               "a frame declares " + std::to_string(bytes) + " bytes (4 to " + std::to_string(kMaxRpcFrameBytes) +
                   " allowed): the connection is dropped");
        ++dropped_;
        return;
      case sv::FramedDrop::Flood:
        reject("flood", "a client sent more than " + std::to_string(kMaxFramesPerSecond) + " frames in a second: dropped");
        ++dropped_;
        return;
      case sv::FramedDrop::SlowReader:
        reject("slow_reader", "a client read nothing of " + std::to_string(bytes) + " bytes waiting: dropped");
        ++dropped_;
        return;
      case sv::FramedDrop::TooManyClients:
        reject("too_many_clients", "more than " + std::to_string(sv::kMaxConnections) +
                                       " clients at once, none idle for 2 s: refused");
        return;
      case sv::FramedDrop::IdleEvicted:
        reject("idle_evicted", "a client that sent nothing for " + std::to_string(bytes) +
                                   " s (and started no data feed) made room for a new one: dropped");
        ++dropped_;
        return;
      case sv::FramedDrop::OutOfDescriptors:
        reject("out_of_descriptors", std::string("cannot accept a client: ") + std::strerror(static_cast<int>(bytes)) +
                                         " (ulimit -n): accepting pauses 100 ms; raise the limit if this is not an attack");
        return;
    }
  }

  void closing(sv::FramedConnection&, std::size_t, bool stopping) override {
    if (!stopping) spdlog::info("monado {}: a client left", path_);
  }

  std::string path_;
  std::uint16_t mask_;
  std::string names_;
  sx::SteamvrToggles toggles_;
  sx::BoneMap bones_;        // built on the reconstruction thread (set_skeleton), read there
  std::vector<int> joints_;  // per synthetic tracker
  std::vector<sx::SyntheticTracker> work_trackers_;
  std::vector<sx::Bone> work_bones_;
  sx::Encoder send_encoder_;  // reconstruction thread

  sv::FramedServer server_;  // its mutex() guards what follows
  std::vector<sx::SyntheticTracker> latest_trackers_;
  std::vector<sx::Bone> latest_bones_;
  sx::Encoder thread_encoder_;
  std::vector<std::uint8_t> scratch_;
  std::uint64_t poses_ = 0, updates_without_bones_ = 0;
  std::int64_t last_interval_ms_ = 0;
  std::uint64_t updates_sent_ = 0, polls_answered_ = 0, settings_answered_ = 0, updates_without_client_ = 0,
                dropped_ = 0, rejected_ = 0, connections_total_ = 0;
  std::map<std::string, std::uint64_t> rejected_by_reason_;
};

}  // namespace

std::unique_ptr<Output> make_monado_output(const OutputSpec& spec, const OutputEnv&, std::string& error) {
  // DIR/SlimeVRRpc, DIR by default $XDG_RUNTIME_DIR.
  const SocketOfTarget rpc_socket = [](const std::string& target, std::string& e) {
    const std::string dir = target.empty() ? sv::default_socket_dir(e) : target;
    return dir.empty() ? std::string() : sv::socket_path(dir + "/" + std::string(sv::kMonadoRpcSocketName), {}, e);
  };
  PlaceMask mask = 0;
  std::string path;
  if (!body_tracker_output_spec(spec, rpc_socket, mask, path, error)) return nullptr;
  return std::make_unique<MonadoOutput>(path, mask);
}

}  // namespace bodyd::daemon
