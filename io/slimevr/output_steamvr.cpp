// `--output steamvr[:SOCKET][?trackers=waist,feet,...]`: virtual trackers in SteamVR through
// SlimeVR's OpenVR driver (drivers/slimevr_bridge.h, docs/outputs.md "steamvr").
#include "bodyd/io/output.h"
#include "bodyd/io/slimevr/slimevr_bridge.h"
#include "output_parts.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <array>
#include <atomic>
#include <memory>
#include <optional>

namespace bodyd::daemon {

namespace {

namespace sv = drivers::slimevr;

// SlimeVR's role numbers of kBodyTrackers (output_parts.h), in its order: also the tracker ids,
// so they are stable across connections and restarts (docs/outputs.md). The serial is
// "bodyd-" + the tracker's name.
constexpr std::array<std::int32_t, kBodyTrackers.size()> kRoles{sv::role::kWaist,     sv::role::kLeftFoot,
                                                               sv::role::kRightFoot, sv::role::kChest,
                                                               sv::role::kLeftKnee,  sv::role::kRightKnee,
                                                               sv::role::kLeftElbow, sv::role::kRightElbow};
// bodyd's role of each of kBodyTrackers: a real tracker of that role in SteamVR leaves the
// virtual one out.
constexpr std::array<Role, kBodyTrackers.size()> kTrackerRoles{Role::Hips,     Role::LeftFoot,  Role::RightFoot,
                                                              Role::Chest,    Role::LeftKnee,  Role::RightKnee,
                                                              Role::LeftElbow, Role::RightElbow};

class SteamvrOutput final : public Output {
 public:
  SteamvrOutput(std::string path, PlaceMask mask)
      : path_(std::move(path)), mask_(mask), server_(sv::shared_bridge(path_)), names_(place_names(kBodyTrackers, mask_)) {
    for (std::size_t i = 0; i < kBodyTrackers.size(); ++i) {
      if (!(mask_ & (1u << i))) continue;
      const std::string name(kBodyTrackers[i].name);
      announced_.push_back({kRoles[i], "bodyd-" + name, "bodyd " + name, kRoles[i]});
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
    joints_.find(skeleton, kBodyTrackers, mask_, name(), "trackers");
  }

  // SteamVR owns the head: the trackers go back into the space the headset's samples came in.
  OutputSpace space() const override { return OutputSpace::Runtime; }

  bool send(const OutputFrame& frame, std::string& out_error) override {
    if (!joints_.complete(out_error)) return false;
    leave_out_real_trackers(frame);
    const GlobalPose& g = frame.body.global;  // the driver's space (space())
    std::size_t n = 0;
    for (int j : joints_.indices()) {
      if (j < 0 || j >= static_cast<int>(g.positions.size()) || j >= static_cast<int>(g.rotations.size())) {
        out_error = "the pose has fewer joints than its skeleton";
        return false;
      }
      const auto k = static_cast<std::size_t>(j);
      poses_[n].id = announced_[n].id;
      poses_[n].position_m = g.positions[k];
      poses_[n].rotation = g.rotations[k];
      ++n;
    }
    // A pose whose headset is lost (rotation only, occluded, gone) is a guess: the trackers are
    // reported OCCLUDED until the headset is tracked again (docs/outputs.md "steamvr").
    return server_->publish(poses_.data(), n, frame.head_as_received.valid, out_error);
  }

  nlohmann::json status() const override {
    const sv::BridgeStats b = server_->stats();
    return {{"trackers", names_},
            {"trackers_left_out", place_names(kBodyTrackers, left_out_.load())},
            {"socket", path_},
            {"clients", b.clients},
            {"connections", b.connections},
            {"positions_sent", b.frames_out},
            {"poses_without_client", b.publishes_without_client},
            {"dropped", b.dropped},
            {"rejected", b.rejected},
            {"rejected_by_reason", b.rejected_by_reason},
            {"devices_in", b.roles_in},
            {"trackers_status", b.trackers_tracked ? "ok" : "occluded"},
            {"statuses_sent", b.statuses_out}};
  }

  void close() override {
    if (!open_) return;
    server_->stop();
    open_ = false;
  }

 private:
  // A role the user tracks is not replaced by a guess: where SteamVR's driver (the steamvr:
  // source on this socket) sent a sample of a tracker's role within kRealTrackerHoldNs (output.h),
  // SteamVR has the real tracker, and the virtual one is left out (not announced, or OCCLUDED
  // where it was) until the real one has been gone that long (docs/outputs.md, "Tracked roles").
  void leave_out_real_trackers(const OutputFrame& frame) {
    const std::optional<std::uint16_t> runtime = server_->source_index();
    PlaceMask out = 0;
    for (std::size_t i = 0; runtime && i < kBodyTrackers.size(); ++i) {
      const RoleArrival& a = frame.role_arrivals[static_cast<std::size_t>(kTrackerRoles[i])];
      if ((mask_ & (1u << i)) && a.source_index == *runtime && real_tracker_recent(a, frame.arrival_ns))
        out |= static_cast<PlaceMask>(1u << i);
    }
    const PlaceMask was = left_out_.load();
    if (out == was) return;
    std::vector<std::int32_t> ids;
    for (std::size_t i = 0; i < kBodyTrackers.size(); ++i)
      if (out & (1u << i)) ids.push_back(kRoles[i]);
    server_->set_left_out(std::move(ids));
    left_out_.store(out);
    if (const auto gone = static_cast<PlaceMask>(out & ~was))
      spdlog::info("{}: {} left out: SteamVR has real trackers for them (their samples reach bodyd)", name(),
                   place_names(kBodyTrackers, gone));
    if (const auto back = static_cast<PlaceMask>(was & ~out))
      spdlog::info("{}: {} back: their real trackers sent nothing for {} s", name(), place_names(kBodyTrackers, back),
                   kRealTrackerHoldNs / 1'000'000'000);
  }

  std::string path_;
  PlaceMask mask_;
  std::shared_ptr<sv::BridgeServer> server_;
  std::vector<sv::AnnouncedTracker> announced_;
  std::string names_;
  PlaceJoints joints_;
  std::array<sv::TrackerPoseOut, kBodyTrackers.size()> poses_{};
  std::atomic<PlaceMask> left_out_{0};  // the reconstruction thread's; status reads it
  bool open_ = false;
};

}  // namespace

std::unique_ptr<Output> make_steamvr_output(const OutputSpec& spec, const OutputEnv&, std::string& error) {
  // SOCKET, default $XDG_DATA_HOME/dev.slimevr.SlimeVR/SlimeVRDriver (where the driver finds it
  // from inside SteamVR's container).
  const SocketOfTarget driver_socket = [](const std::string& target, std::string& e) {
    return sv::socket_path(target, sv::kDriverSocketName, e, sv::default_driver_socket_dir);
  };
  PlaceMask mask = 0;
  std::string path;
  if (!body_tracker_output_spec(spec, driver_socket, mask, path, error)) return nullptr;
  sv::warn_if_shadowed(path);
  return std::make_unique<SteamvrOutput>(path, mask);
}

}  // namespace bodyd::daemon
