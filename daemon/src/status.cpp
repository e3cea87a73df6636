#include "status.h"

#include "bodyd/daemon/config.h"
#include "bodyd/io/zmq/pose_wire.h"
#include "sample_conditioning.h"

namespace bodyd::daemon {

using nlohmann::json;

void summary_json(const ReconstructionSummary& summary, json& out) {
  out["head_height_m"] = summary.head_height_m;
  out["user_height_m"] = summary.head_height_m / kHeadHeightPerStature;
  summary.calibration.to_json(out);
  out["skeleton_id"] = summary.skeleton.skeleton_id;
}

json skeleton_reply(const protocol::SkeletonMessage& skeleton, double head_height_m) {
  json offsets = json::array();
  for (const auto& o : skeleton.offsets_m) offsets.push_back({o[0], o[1], o[2]});
  json reply{{"ok", true},
             {"skeleton_id", skeleton.skeleton_id},
             {"names", skeleton.names},
             {"parents", skeleton.parents},
             {"offsets_m", offsets},
             {"head_height_m", head_height_m}};
  if (!skeleton.rest_rotations_xyzw.empty()) reply["rest_rotations_xyzw"] = rest_rotations_json(skeleton);
  return reply;
}

json source_status_json(const drivers::SourceStatus& st, const std::array<double, kRoleCount>& rate_hz_by_role) {
  json by_role = json::object();
  // The headset's and controllers' always, a body tracker's while it sends.
  for (Role r : kRoles)
    if (is_xr_role(r) || rate_hz_by_role[static_cast<std::size_t>(r)] > 0.0)
      by_role[std::string(role_name(r))] = rate_hz_by_role[static_cast<std::size_t>(r)];
  json j{{"name", st.name},
          {"connected", st.connected},
          {"finished", st.finished},
          {"samples", st.samples},
          {"rate_hz", st.rate_hz},
          {"rate_hz_by_role", by_role},
          {"last_error", st.last_error},
          {"rejected", st.rejected},
          {"rejected_by_reason", st.rejected_by_reason},
          {"counters", st.counters}};
  if (!st.devices.empty()) j["devices"] = st.devices;
  return j;
}

json mounting_status_json(const Mounting& mounting, const Mounting& defaults, const MountingOrigins& origins,
                          const SampleConditioner& conditioner, const std::string& mounting_file) {
  json roles = json::object();
  for (Role r : kRoles) {
    const int i = static_cast<int>(r);
    // Body trackers: listed once measured (their device poses are not used before).
    if (!is_xr_role(r) && origins[i] == MountingOrigin::Default) continue;
    const RigidTransform& T = mounting.T_device_joint[i];
    const MountingDifference d = mounting_difference(T, defaults.T_device_joint[i]);
    roles[std::string(role_name(r))] = {{"origin", std::string(name(origins[i]))},
                                        {"device_frames", conditioner.device_frames_seen(r)},
                                        {"position_m", {T.position_m.x(), T.position_m.y(), T.position_m.z()}},
                                        {"rotation_xyzw", {T.rotation.x(), T.rotation.y(), T.rotation.z(), T.rotation.w()}},
                                        {"from_default_deg", d.angle_deg},
                                        {"from_default_cm", d.position_cm}};
    if (!is_xr_role(r)) {  // no default to compare with: how far the device sits from its joint
      json& o = roles[std::string(role_name(r))];
      o.erase("from_default_deg");
      o.erase("from_default_cm");
      o["offset_cm"] = 100.0 * T.position_m.norm();
    }
  }
  return json{{"roles", roles}, {"file", mounting_file}};
}

json status_json(const StatusSnapshot& s, const PipelineStats& stats) {
  json j = json::object();
  j["ok"] = true;
  j["uptime_s"] = s.uptime_s;
  j["method"] = s.summary.method;
  j["model"] = s.summary.model_path;
  summary_json(s.summary, j);
  j["offsets_configured"] = s.offsets_configured;
  j.update(s.recentre);
  j["mounting"] = s.mounting;
  if (!s.record_trackers_file.empty()) j["record_trackers"] = s.record_trackers_file;
  json src = json::array();
  for (std::size_t i = 0; i < s.sources.size(); ++i)
    src.push_back(source_status_json(
        s.sources[i], i < s.source_rates_hz_by_role.size() ? s.source_rates_hz_by_role[i] : std::array<double, kRoleCount>{}));
  j["sources"] = src;
  // Every role with its source, rate and state (issue 44): the headset's and controllers' always,
  // a body tracker's once it has sent something.
  json trackers = json::object();
  for (Role r : kRoles) {
    const RoleSeen& seen = s.trackers[static_cast<std::size_t>(r)];
    if (seen.arrival_ns == INT64_MIN) {
      if (is_xr_role(r)) trackers[std::string(role_name(r))] = {{"state", "none yet"}};
      continue;
    }
    json t;
    const double age_s = static_cast<double>(s.now_ns - seen.arrival_ns) * 1e-9;
    const bool silent = s.now_ns - seen.arrival_ns > RoleRateSink::kSilentNs;  // as the rates
    t["state"] = silent                                    ? "silent"
                 : !(seen.flags & RoleSeen::kUsed)         ? "not used: mounting not calibrated"
                 : !(seen.flags & RoleSeen::kValid)        ? "lost"
                 : !(seen.flags & RoleSeen::kPosition)     ? "rotation only"
                                                           : "tracked";
    t["age_s"] = age_s;
    if (seen.source >= 0 && static_cast<std::size_t>(seen.source) < s.sources.size()) {
      t["source"] = s.sources[static_cast<std::size_t>(seen.source)].name;
      if (static_cast<std::size_t>(seen.source) < s.source_rates_hz_by_role.size())
        t["rate_hz"] = s.source_rates_hz_by_role[static_cast<std::size_t>(seen.source)][static_cast<std::size_t>(r)];
    }
    trackers[std::string(role_name(r))] = std::move(t);
  }
  j["trackers"] = std::move(trackers);
  j["sources_started"] = s.sources_started;
  stats.to_json(j);
  j["samples_dropped"] = s.samples_dropped;
  j["samples_dropped_stale"] = s.samples_dropped_stale;
  j["queue_depth"] = s.queue_depth;
  j["queue_capacity"] = s.queue_capacity;
  j["sends_failed"] = j["sends_failed"].get<std::uint64_t>() + s.pub_skeleton_sends_failed;
  j["subscriptions"] = s.pub_subscriptions;
  j["pub"] = s.pub;
  j["control"] = s.control;
  j["curve"] = s.curve;
  j["rate_hz"] = s.rate_hz;
  j["outputs"] = s.outputs;
  return j;
}

}  // namespace bodyd::daemon
