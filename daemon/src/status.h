// The daemon's `status` reply and the parts the other control replies share (docs/control.md):
// built here from a snapshot the daemon takes (daemon.cpp), so the keys live in one place.
#pragma once

#include "bodyd/io/source.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/protocol/pose_message.h"
#include "calibration_state.h"
#include "stats.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace bodyd {
class SampleConditioner;  // bodyd/inference/sample_conditioning.h
}

namespace bodyd::daemon {

// What the reconstruction is now: written by the reconstruction thread (and start()), read by
// the control thread, both under the daemon's lock.
struct ReconstructionSummary {
  std::string method;      // the reconstructor's name
  std::string model_path;  // empty for ik
  double head_height_m = 0.0;
  CalibrationState calibration;
  protocol::SkeletonMessage skeleton;
};

// head_height_m, user_height_m (the body height it means), height_calibrated,
// calibration_source, auto_calibration and skeleton_id into `out`.
void summary_json(const ReconstructionSummary& summary, nlohmann::json& out);
// The reply to {"cmd":"skeleton"} (docs/protocol.md "The skeleton on the control socket").
[[nodiscard]] nlohmann::json skeleton_reply(const protocol::SkeletonMessage& skeleton, double head_height_m);
// One source's entry in status "sources", with its rate role by role (RoleRateSink).
[[nodiscard]] nlohmann::json source_status_json(const drivers::SourceStatus& status,
                                                const std::array<double, kRoleCount>& rate_hz_by_role);
// status "mounting": each role's mounting, where it came from and how far from the default.
[[nodiscard]] nlohmann::json mounting_status_json(const Mounting& mounting, const Mounting& defaults,
                                                  const MountingOrigins& origins, const SampleConditioner& conditioner,
                                                  const std::string& mounting_file);

// Everything `status` says, as the daemon gathered it.
// One role's newest sample as the reconstruction thread saw it (status's `trackers`, issue 44):
// written with relaxed atomics per sample, read by the control thread.
struct RoleSeen {
  static constexpr std::uint8_t kValid = 1, kPosition = 2, kUsed = 4;
  std::int64_t arrival_ns = INT64_MIN;  // host monotonic; INT64_MIN: none yet
  int source = -1;                      // index into the sources
  std::uint8_t flags = 0;
};

struct StatusSnapshot {
  double uptime_s = 0.0;
  std::int64_t now_ns = 0;
  std::array<RoleSeen, kRoleCount> trackers{};
  ReconstructionSummary summary;
  bool offsets_configured = false;
  nlohmann::json recentre;  // recentre_status_json() (sample_conditioning.h)
  nlohmann::json mounting;  // mounting_status_json()
  std::string record_trackers_file;
  std::vector<drivers::SourceStatus> sources;
  std::vector<std::array<double, kRoleCount>> source_rates_hz_by_role;  // parallel to `sources`
  bool sources_started = false;
  std::uint64_t samples_dropped = 0, samples_dropped_stale = 0;
  std::size_t queue_depth = 0, queue_capacity = 0;
  // The --pub output's endpoint.
  std::string pub, control;
  std::uint64_t pub_subscriptions = 0, pub_skeleton_sends_failed = 0;
  bool curve = false;
  double rate_hz = 0.0;
  nlohmann::json outputs = nlohmann::json::array();  // one entry per output
};
[[nodiscard]] nlohmann::json status_json(const StatusSnapshot& snapshot, const PipelineStats& stats);

}  // namespace bodyd::daemon
