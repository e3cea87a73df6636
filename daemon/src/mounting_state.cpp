#include "mounting_state.h"

#include "bodyd/motion/limits.h"
#include "bodyd/motion/printable.h"
#include "persisted_file.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>

namespace bodyd::daemon {

using nlohmann::json;

namespace {

constexpr double kMaxOffsetM = 0.5;  // a device is never half a metre from its joint
constexpr const char* kFormat = "bodyd-mounting v1";
constexpr const char* kWhatToDo = "delete the file and run `bodyd-ctl calibrate --pose` again; docs/daemon.md";

// The member `key` of object `o`, nullptr when it has none.
const json* member(const json& o, const char* key) {
  const auto it = o.find(key);
  return it == o.end() ? nullptr : &*it;
}

// `n` finite numbers from the array `key` of `o` into `out`; false when it is anything else.
bool finite_numbers(const json& o, const char* key, std::size_t n, double* out) {
  const json* a = member(o, key);
  if (!a || !a->is_array() || a->size() != n) return false;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(*a)[i].is_number()) return false;
    out[i] = (*a)[i].get<double>();
    if (!std::isfinite(out[i])) return false;
  }
  return true;
}

}  // namespace

std::optional<MountingState> read_mounting_state(const std::filesystem::path& path, const Mounting& defaults,
                                                 const PoseCalibrationOptions& limits, std::string& error) {
  const auto fail = [&](const std::string& what) -> std::optional<MountingState> {
    error = fmt::format("{}: {} ({})", path.string(), what, kWhatToDo);
    return std::nullopt;
  };
  const std::optional<std::string> text = read_persisted_file(path, kMaxPersistedFileBytes, error);
  if (!text) {
    if (!error.empty()) error = fmt::format("{} ({})", error, kWhatToDo);
    return std::nullopt;
  }
  json j;
  try {
    j = json::parse(*text);
  } catch (const json::exception& e) {
    return fail(std::string("not JSON: ") + e.what());
  }
  // Every member by its type before its value: json::value() and get() throw on a wrong type.
  if (!j.is_object()) return fail("not a JSON object");
  const json* format = member(j, "format");
  if (!format || !format->is_string() || format->get<std::string>() != kFormat)
    return fail(fmt::format("\"format\" is not \"{}\"", kFormat));
  MountingState st;
  if (const json* calibrated = member(j, "calibrated")) {
    if (!calibrated->is_string()) return fail("\"calibrated\" is not a string (the UTC time of the calibration)");
    st.calibrated = printable(calibrated->get<std::string>());  // it goes to the log
  }
  if (const json* height = member(j, "head_height_m")) {
    if (!height->is_number()) return fail("\"head_height_m\" is not a number");
    st.head_height_m = height->get<double>();
    if (!(st.head_height_m == 0.0 ||
          (st.head_height_m >= limits::kMinHeadHeightM && st.head_height_m <= limits::kMaxHeadHeightM)))
      return fail(fmt::format("\"head_height_m\" {} is not a plausible standing head height", st.head_height_m));
  }
  const json* roles = member(j, "roles");
  if (!roles || !roles->is_object()) return fail("\"roles\" is not an object");
  for (Role r : kRoles) {
    const auto i = static_cast<std::size_t>(r);
    const std::string name(role_name(r));
    const json* o = member(*roles, name.c_str());
    // Body trackers' roles are there only once one was measured (and not in files written before).
    if (!o && !is_xr_role(r)) continue;
    if (!o || !o->is_object()) return fail(fmt::format("roles.{} is not an object", name));
    if (const json* measured = member(*o, "measured")) {
      if (!measured->is_boolean()) return fail(fmt::format("roles.{}.measured is not true or false", name));
      st.measured[i] = measured->get<bool>();
    }
    double p[3], q[4];
    if (!finite_numbers(*o, "position_m", 3, p)) return fail(fmt::format("roles.{}.position_m is not 3 finite numbers", name));
    if (!finite_numbers(*o, "rotation_xyzw", 4, q))
      return fail(fmt::format("roles.{}.rotation_xyzw is not 4 finite numbers", name));
    const Vec3 pos(p[0], p[1], p[2]);
    const double max_offset_m = is_xr_role(r) ? kMaxOffsetM : kMaxBodyTrackerOffsetM;  // as the calibration pose
    if (pos.norm() > max_offset_m)
      return fail(fmt::format("roles.{}.position_m is more than {} m from the joint", name, max_offset_m));
    const Quat rot(q[3], q[0], q[1], q[2]);
    if (std::abs(rot.norm() - 1.0) > limits::kQuatNormTolerance)
      return fail(fmt::format("roles.{}.rotation_xyzw is not a unit quaternion", name));
    st.mounting.T_device_joint[i] = {pos, rot.normalized()};
    // The limits of the calibration pose that wrote it: a rotation typed by hand (identity is
    // 125 degrees from the headset's default) would tilt every pose.
    const double change_deg = mounting_difference(st.mounting.T_device_joint[i], defaults.T_device_joint[i]).angle_deg;
    // A body tracker may be strapped turned any way: only its offset is limited (above).
    const double max_deg = max_mounting_change_deg(limits, r);
    if (is_xr_role(r) && st.measured[i] && change_deg > max_deg) {
      st.measured[i] = false;
      st.refused.push_back(fmt::format("{}: roles.{}.rotation_xyzw is {:.0f} degrees from the default mounting, more "
                                       "than the {:.0f} a calibration pose accepts: the default {} mounting is used ({})",
                                       path.string(), name, change_deg, max_deg, name, kWhatToDo));
    }
  }
  return st;
}

std::string write_mounting_state(const std::filesystem::path& path, const MountingState& st) {
  json roles = json::object();
  for (Role r : kRoles) {
    if (!is_xr_role(r) && !st.measured[static_cast<std::size_t>(r)]) continue;
    const RigidTransform& T = st.mounting.T_device_joint[static_cast<std::size_t>(r)];
    roles[std::string(role_name(r))] = {
        {"measured", st.measured[static_cast<std::size_t>(r)]},
        {"position_m", {T.position_m.x(), T.position_m.y(), T.position_m.z()}},
        {"rotation_xyzw", {T.rotation.x(), T.rotation.y(), T.rotation.z(), T.rotation.w()}}};
  }
  const json j{{"format", kFormat}, {"calibrated", st.calibrated}, {"head_height_m", st.head_height_m}, {"roles", roles}};
  if (path.has_parent_path()) {
    if (std::string e = create_private_directories(path.parent_path()); !e.empty()) return e;
  }
  return replace_persisted_file(path, j.dump(2) + "\n", 0600);
}

}  // namespace bodyd::daemon
