// `--output monado[:DIR][?trackers=...]`: bodyd as the SolarXR server of Monado's SolarXR driver
// on DIR/SlimeVRRpc (default $XDG_RUNTIME_DIR): bones and synthetic trackers in DataFeedUpdates
// (bodyd/daemon/solarxr.h, docs/protocol-solarxr.md, docs/outputs.md "monado").
//
// One thread (drivers' FramedServer, bodyd/drivers/framed_server.h) accepts and reads the
// clients' MessageBundles; this output answers each PollDataFeed at once with the latest pose
// (Monado waits at most 4 s for the first, before any pose may exist) and each SettingsRequest
// with the SteamVR tracker toggles; send() (the reconstruction thread) sends one DataFeedUpdate
// per pose to the clients that sent a StartDataFeed, without blocking.
#include "bodyd/daemon/output.h"
#include "bodyd/daemon/solarxr.h"
#include "bodyd/drivers/framed_server.h"
#include "bodyd/drivers/slimevr_bridge.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

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

struct MonadoTracker {
  std::string_view name;
  std::uint8_t body_part;
  std::string_view joint;
};
constexpr std::array<MonadoTracker, 8> kTrackers{{{"waist", sx::part::kHip, "Hips"},
                                                   {"left_foot", sx::part::kLeftFoot, "Foot_L"},
                                                   {"right_foot", sx::part::kRightFoot, "Foot_R"},
                                                   {"chest", sx::part::kChest, "Chest"},
                                                   {"left_knee", sx::part::kLeftLowerLeg, "LowerLeg_L"},
                                                   {"right_knee", sx::part::kRightLowerLeg, "LowerLeg_R"},
                                                   {"left_elbow", sx::part::kLeftLowerArm, "LowerArm_L"},
                                                   {"right_elbow", sx::part::kRightLowerArm, "LowerArm_R"}}};

bool parse_trackers(std::string_view text, std::uint16_t& out, std::string& error) {
  out = 0;
  std::string_view rest = text;
  while (true) {
    const auto comma = rest.find(',');
    const std::string_view name = rest.substr(0, comma);
    std::uint16_t bits = 0;
    if (name == "feet") bits = 0b0000'0110;
    else if (name == "knees") bits = 0b0011'0000;
    else if (name == "elbows") bits = 0b1100'0000;
    else if (name == "hip") bits = 1;
    for (std::size_t i = 0; i < kTrackers.size(); ++i)
      if (kTrackers[i].name == name) bits = static_cast<std::uint16_t>(1u << i);
    if (bits == 0) {
      error = "tracker \"" + std::string(name) +
              "\": expected waist, feet, knees, chest, elbows, left_foot, right_foot, left_knee, right_knee, "
              "left_elbow or right_elbow";
      return false;
    }
    out |= bits;
    if (comma == std::string_view::npos) return true;
    rest = rest.substr(comma + 1);
  }
}

class MonadoOutput final : public Output, sv::FramedHandler {
 public:
  MonadoOutput(std::string path, std::uint16_t mask)
      : path_(std::move(path)), mask_(mask), server_(path_, kLimits, *this) {
    for (std::size_t i = 0; i < kTrackers.size(); ++i) {
      if (!(mask_ & (1u << i))) continue;
      sx::SyntheticTracker t;
      t.tracker_num = static_cast<std::uint8_t>(i + 1);
      t.body_part = kTrackers[i].body_part;
      t.display_name = "bodyd " + std::string(kTrackers[i].name);
      latest_trackers_.push_back(t);
      names_ += (names_.empty() ? "" : ",") + std::string(kTrackers[i].name);
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
    joints_.clear();
    for (std::size_t i = 0; i < kTrackers.size(); ++i)
      if (mask_ & (1u << i)) joints_.push_back(skeleton.find(kTrackers[i].joint));
  }

  bool send(const OutputFrame& frame, std::string& out_error) override {
    const GlobalPose& g = frame.body.global;
    const Quat undo = frame.recentre_rotation.conjugate();
    const Vec3& t = frame.recentre_translation_m;
    for (std::size_t i = 0; i < joints_.size(); ++i) {
      const int j = joints_[i];
      sx::SyntheticTracker& st = work_trackers_[i];
      st.has_pose = j >= 0 && j < static_cast<int>(g.positions.size());
      if (!st.has_pose) continue;
      st.position_m = undo * (g.positions[static_cast<std::size_t>(j)] - t);
      st.rotation = (undo * g.rotations[static_cast<std::size_t>(j)]).normalized();
    }
    if (bones_.ready()) bones_.bones(g, undo, t, work_bones_);
    std::lock_guard lock(server_.mutex());
    std::swap(latest_trackers_, work_trackers_);
    std::swap(latest_bones_, work_bones_);
    work_trackers_ = latest_trackers_;  // same size: no allocation
    bool any = false, dropped = false;
    std::pair<const std::uint8_t*, std::size_t> bytes{nullptr, 0};
    for (const auto& c : server_.connections()) {
      if (c->drop || !static_cast<Connection&>(*c).streaming) continue;
      if (bytes.first == nullptr) bytes = send_encoder_.update(latest_trackers_, false, latest_bones_);
      append_frame(*c, bytes);
      ++updates_sent_;
      any = true;
      server_.flush(*c);
      dropped |= c->drop;
    }
    if (!any) ++updates_without_client_;
    if (dropped) {
      server_.wake();
      out_error = "a client that does not read was dropped";
      return false;
    }
    return true;
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
  };

  void reject(const std::string& reason, const std::string& detail) {
    ++rejected_;
    const std::uint64_t n = ++rejected_by_reason_[reason];
    if ((n & (n - 1)) == 0)
      spdlog::warn("monado {}: {} ({}; {} so far, logged at the 1st, 2nd, 4th, 8th...)", path_, detail, reason, n);
  }

  static void append_frame(sv::FramedConnection& c, std::pair<const std::uint8_t*, std::size_t> bytes) {
    const auto framed = static_cast<std::uint32_t>(bytes.second + sv::kFrameHeaderBytes);
    const std::size_t at = c.out.size();
    c.out.resize(at + framed);
    for (int k = 0; k < 4; ++k) c.out[at + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>((framed >> (8 * k)) & 0xff);
    std::memcpy(c.out.data() + at + sv::kFrameHeaderBytes, bytes.first, bytes.second);
  }

  void handle(Connection& c, const sx::Request& r) {
    if (r.stop_feed) c.streaming = false;
    if (r.start_feed) c.streaming = true;
    for (int i = 0; i < r.polls; ++i) {
      // The first answer names the trackers (Monado makes its generic trackers from it).
      append_frame(c, thread_encoder_.update(latest_trackers_, true, latest_bones_));
      ++polls_answered_;
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

  void frame(sv::FramedConnection& c, const std::uint8_t* payload, std::size_t size, std::int64_t) override {
    // FlatBuffers' verifier wants the buffer aligned: copy the payload to the start of one.
    scratch_.assign(payload, payload + size);
    sx::Request r;
    std::string error;
    if (!sx::decode_request(scratch_.data(), scratch_.size(), r, error)) {
      reject("malformed", error);
      return;
    }
    handle(static_cast<Connection&>(c), r);
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
        reject("too_many_clients", "more than " + std::to_string(sv::kMaxConnections) + " clients at once: refused");
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
  std::uint64_t updates_sent_ = 0, polls_answered_ = 0, settings_answered_ = 0, updates_without_client_ = 0,
                dropped_ = 0, rejected_ = 0, connections_total_ = 0;
  std::map<std::string, std::uint64_t> rejected_by_reason_;
};

}  // namespace

std::unique_ptr<Output> make_monado_output(const OutputSpec& spec, const OutputEnv& env, std::string& error) {
  (void)env;
  if (std::string e = check_options(spec, {"trackers"}); !e.empty()) {
    error = e;
    return nullptr;
  }
  std::uint16_t mask = 0b0000'0111;  // waist and feet
  if (const auto it = spec.options.find("trackers"); it != spec.options.end()) {
    if (!parse_trackers(it->second, mask, error)) {
      error = "--output " + spec.text + ": " + error;
      return nullptr;
    }
  }
  std::string e;
  std::string dir = spec.target;
  if (dir.empty()) dir = sv::default_socket_dir(e);
  const std::string path = dir.empty() ? std::string() : sv::socket_path(dir + "/" + std::string(sv::kMonadoRpcSocketName), {}, e);
  if (path.empty()) {
    error = "--output " + spec.text + ": " + e;
    return nullptr;
  }
  return std::make_unique<MonadoOutput>(path, mask);
}

}  // namespace bodyd::daemon
