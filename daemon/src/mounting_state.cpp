#include "mounting_state.h"

#include "bodyd/motion/limits.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <sstream>
#include <sys/stat.h>

namespace bodyd::daemon {

using nlohmann::json;

namespace {

constexpr double kMaxOffsetM = 0.5;  // a device is never half a metre from its joint

}  // namespace

std::optional<MountingState> read_mounting_state(const std::filesystem::path& path, std::string& error) {
  error.clear();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return std::nullopt;
  const auto fail = [&](const std::string& what) -> std::optional<MountingState> {
    error = fmt::format("{}: {} (delete the file and run `bodyd-ctl calibrate --pose` again; docs/daemon.md)",
                        path.string(), what);
    return std::nullopt;
  };
  if (!std::filesystem::is_regular_file(path, ec)) return fail("not a regular file");
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  if (!in && !in.eof()) return fail("cannot be read");
  json j;
  try {
    j = json::parse(ss.str());
  } catch (const json::exception& e) {
    return fail(std::string("not JSON: ") + e.what());
  }
  if (!j.is_object() || j.value("format", "") != "bodyd-mounting v1") return fail("\"format\" is not \"bodyd-mounting v1\"");
  if (!j.contains("roles") || !j["roles"].is_object()) return fail("\"roles\" is missing");
  MountingState st;
  st.calibrated = j.value("calibrated", "");
  if (j.contains("head_height_m")) {
    if (!j["head_height_m"].is_number()) return fail("\"head_height_m\" is not a number");
    st.head_height_m = j["head_height_m"].get<double>();
    if (!(st.head_height_m == 0.0 ||
          (st.head_height_m >= limits::kMinHeadHeightM && st.head_height_m <= limits::kMaxHeadHeightM)))
      return fail(fmt::format("\"head_height_m\" {} is not a plausible standing head height", st.head_height_m));
  }
  for (Role r : kRoles) {
    const std::string name(role_name(r));
    if (!j["roles"].contains(name)) return fail(fmt::format("roles.{} is missing", name));
    const json& o = j["roles"][name];
    const auto numbers = [&](const char* key, std::size_t n, double* out) -> bool {
      if (!o.is_object() || !o.contains(key) || !o[key].is_array() || o[key].size() != n) return false;
      for (std::size_t i = 0; i < n; ++i) {
        if (!o[key][i].is_number()) return false;
        out[i] = o[key][i].get<double>();
        if (!std::isfinite(out[i])) return false;
      }
      return true;
    };
    double p[3], q[4];
    if (!numbers("position_m", 3, p)) return fail(fmt::format("roles.{}.position_m is not 3 finite numbers", name));
    if (!numbers("rotation_xyzw", 4, q)) return fail(fmt::format("roles.{}.rotation_xyzw is not 4 finite numbers", name));
    const Vec3 pos(p[0], p[1], p[2]);
    if (pos.norm() > kMaxOffsetM) return fail(fmt::format("roles.{}.position_m is more than {} m from the joint", name, kMaxOffsetM));
    const Quat rot(q[3], q[0], q[1], q[2]);
    if (std::abs(rot.norm() - 1.0) > limits::kQuatNormTolerance)
      return fail(fmt::format("roles.{}.rotation_xyzw is not a unit quaternion", name));
    st.mounting.T_device_joint[static_cast<std::size_t>(r)] = {pos, rot.normalized()};
    st.measured[static_cast<std::size_t>(r)] = o.value("measured", false);
  }
  return st;
}

std::string write_mounting_state(const std::filesystem::path& path, const MountingState& st) {
  json roles = json::object();
  for (Role r : kRoles) {
    const RigidTransform& T = st.mounting.T_device_joint[static_cast<std::size_t>(r)];
    roles[std::string(role_name(r))] = {
        {"measured", st.measured[static_cast<std::size_t>(r)]},
        {"position_m", {T.position_m.x(), T.position_m.y(), T.position_m.z()}},
        {"rotation_xyzw", {T.rotation.x(), T.rotation.y(), T.rotation.z(), T.rotation.w()}}};
  }
  const json j{{"format", "bodyd-mounting v1"}, {"calibrated", st.calibrated}, {"head_height_m", st.head_height_m}, {"roles", roles}};
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << j.dump(2) << "\n";
    out.close();
    if (!out) return fmt::format("{}: cannot write the mounting file (is its folder writable?)", tmp.string());
  }
  ::chmod(tmp.c_str(), 0600);
  std::filesystem::rename(tmp, path, ec);
  if (ec) return fmt::format("{}: cannot replace it: {}", path.string(), ec.message());
  return {};
}

}  // namespace bodyd::daemon
