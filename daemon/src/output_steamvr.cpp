// `--output steamvr[:SOCKET][?trackers=waist,feet,...]`: virtual trackers in SteamVR through
// SlimeVR's OpenVR driver (drivers/slimevr_bridge.h, docs/outputs.md "steamvr").
#include "bodyd/daemon/output.h"
#include "bodyd/drivers/slimevr_bridge.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <array>
#include <memory>

namespace bodyd::daemon {

namespace {

namespace sv = drivers::slimevr;

// The trackers bodyd can announce: SlimeVR's role numbers (also the tracker ids, so they are
// stable across connections and restarts), and the joint each follows (docs/outputs.md).
struct SteamvrTracker {
  std::string_view name;   // the `trackers` option's name; the serial is "bodyd-" + name
  std::int32_t role;
  std::string_view joint;
};
constexpr std::array<SteamvrTracker, 8> kTrackers{{{"waist", sv::role::kWaist, "Hips"},
                                                    {"left_foot", sv::role::kLeftFoot, "Foot_L"},
                                                    {"right_foot", sv::role::kRightFoot, "Foot_R"},
                                                    {"chest", sv::role::kChest, "Chest"},
                                                    {"left_knee", sv::role::kLeftKnee, "LowerLeg_L"},
                                                    {"right_knee", sv::role::kRightKnee, "LowerLeg_R"},
                                                    {"left_elbow", sv::role::kLeftElbow, "LowerArm_L"},
                                                    {"right_elbow", sv::role::kRightElbow, "LowerArm_R"}}};
using TrackerMask = std::uint16_t;
constexpr TrackerMask kDefaultTrackers = 0b0000'0111;  // waist and feet

bool parse_trackers(std::string_view text, TrackerMask& out, std::string& error) {
  out = 0;
  std::string_view rest = text;
  while (true) {
    const auto comma = rest.find(',');
    const std::string_view name = rest.substr(0, comma);
    TrackerMask bits = 0;
    if (name == "feet") bits = 0b0000'0110;
    else if (name == "knees") bits = 0b0011'0000;
    else if (name == "elbows") bits = 0b1100'0000;
    else if (name == "hip") bits = 0b0000'0001;  // VRChat's slot name, accepted too
    for (std::size_t i = 0; i < kTrackers.size(); ++i)
      if (kTrackers[i].name == name) bits = static_cast<TrackerMask>(1u << i);
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

class SteamvrOutput final : public Output {
 public:
  SteamvrOutput(std::string path, TrackerMask mask) : path_(std::move(path)), mask_(mask), server_(sv::shared_bridge(path_)) {
    for (std::size_t i = 0; i < kTrackers.size(); ++i) {
      if (!(mask_ & (1u << i))) continue;
      const SteamvrTracker& t = kTrackers[i];
      announced_.push_back({t.role, "bodyd-" + std::string(t.name), "bodyd " + std::string(t.name), t.role});
      names_ += (names_.empty() ? "" : ",") + std::string(t.name);
    }
  }
  ~SteamvrOutput() override { close(); }

  std::string name() const override { return "steamvr:" + path_; }

  std::string open() override {
    if (open_) return {};
    server_->set_trackers(announced_);
    if (std::string e = server_->start(); !e.empty()) return "--output " + name() + ": " + e;
    open_ = true;
    return {};
  }

  void set_skeleton(const Skeleton& skeleton, const std::vector<std::uint8_t>&) override {
    joints_.clear();
    missing_.clear();
    for (std::size_t i = 0; i < kTrackers.size(); ++i) {
      if (!(mask_ & (1u << i))) continue;
      const int j = skeleton.find(kTrackers[i].joint);
      if (j < 0) missing_ += (missing_.empty() ? "" : ", ") + std::string(kTrackers[i].joint);
      joints_.push_back(j);
    }
    if (!missing_.empty())
      spdlog::error("--output {}: the skeleton has no joint {} for the configured trackers; nothing is sent", name(), missing_);
  }

  bool send(const OutputFrame& frame, std::string& out_error) override {
    if (!missing_.empty()) {
      out_error = "the skeleton has no joint " + missing_;
      return false;
    }
    const GlobalPose& g = frame.body.global;
    // Back to the driver's space (the one the headset's samples came in): undo the re-centring.
    const Quat undo = frame.recentre_rotation.conjugate();
    std::size_t n = 0;
    for (int j : joints_) {
      if (j < 0 || j >= static_cast<int>(g.positions.size()) || j >= static_cast<int>(g.rotations.size())) {
        out_error = "the pose has fewer joints than its skeleton";
        return false;
      }
      const auto k = static_cast<std::size_t>(j);
      poses_[n].id = announced_[n].id;
      poses_[n].position_m = undo * (g.positions[k] - frame.recentre_translation_m);
      poses_[n].rotation = (undo * g.rotations[k]).normalized();
      ++n;
    }
    return server_->publish(poses_.data(), n, out_error);
  }

  nlohmann::json status() const override {
    const sv::BridgeStats b = server_->stats();
    return {{"trackers", names_},
            {"socket", path_},
            {"clients", b.clients},
            {"connections", b.connections},
            {"positions_sent", b.frames_out},
            {"poses_without_client", b.publishes_without_client},
            {"dropped", b.dropped},
            {"rejected", b.rejected},
            {"rejected_by_reason", b.rejected_by_reason},
            {"devices_in", b.roles_in}};
  }

  void close() override {
    if (!open_) return;
    server_->stop();
    open_ = false;
  }

 private:
  std::string path_;
  TrackerMask mask_;
  std::shared_ptr<sv::BridgeServer> server_;
  std::vector<sv::AnnouncedTracker> announced_;
  std::string names_;
  std::vector<int> joints_;
  std::string missing_;
  std::array<sv::TrackerPoseOut, kTrackers.size()> poses_{};
  bool open_ = false;
};

}  // namespace

std::unique_ptr<Output> make_steamvr_output(const OutputSpec& spec, const OutputEnv& env, std::string& error) {
  (void)env;
  if (std::string e = check_options(spec, {"trackers"}); !e.empty()) {
    error = e;
    return nullptr;
  }
  TrackerMask mask = kDefaultTrackers;
  if (const auto it = spec.options.find("trackers"); it != spec.options.end()) {
    if (!parse_trackers(it->second, mask, error)) {
      error = "--output " + spec.text + ": " + error;
      return nullptr;
    }
  }
  std::string e;
  const std::string path = sv::socket_path(spec.target, sv::kDriverSocketName, e);
  if (path.empty()) {
    error = "--output " + spec.text + ": " + e;
    return nullptr;
  }
  return std::make_unique<SteamvrOutput>(path, mask);
}

}  // namespace bodyd::daemon
