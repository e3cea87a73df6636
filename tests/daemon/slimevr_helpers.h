// Helpers for the SlimeVR-bridge tests (steamvr and monado): the Python client that stands in
// for SlimeVR's OpenVR driver / Monado (tests/drivers/slimevr/driver_client.py, solarxr_client.py),
// the poses file it plays, and what it received.
#pragma once

#include "bodyd/motion/bvh.h"
#include "bodyd/protocol/pose_message.h"
#include "bodyd/simulators/tracker_sim.h"
#include "../test_paths.h"
#include "zmq_helpers.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace bodyd::test::slimevr {

namespace fs = std::filesystem;

using test::find_on_path;

inline fs::path client_script(const char* name) { return source_dir() / "tests" / "drivers" / "slimevr" / name; }
inline fs::path pb_dir() { return BODYD_SLIMEVR_PY_DIR; }

// Empty, or why the Python client cannot run (scripts/setup installs what it needs).
inline std::string python_skip_reason(std::string& out_python, bool flatbuffers = false) {
  // Debian's interpreter first: the Debian packages (python3-protobuf, python3-flatbuffers)
  // are its modules, and a PATH python3 (pyenv, a venv) may not see them.
  out_python = ::access("/usr/bin/python3", X_OK) == 0 ? std::string("/usr/bin/python3") : find_on_path("python3");
  if (out_python.empty()) return "python3 is not installed: run scripts/setup";
  if (!fs::exists(pb_dir() / "driver_messages_pb2.py"))
    return "the test's protobuf module was not generated (" + (pb_dir() / "driver_messages_pb2.py").string() +
           "): protoc missing at configure time? run scripts/setup";
  const std::string check = out_python + " -c 'import google.protobuf" + (flatbuffers ? ", flatbuffers" : "") + "' 2>/dev/null";
  if (std::system(check.c_str()) != 0)
    return std::string("python3-protobuf") + (flatbuffers ? " or python3-flatbuffers" : "") + " is missing: run scripts/setup";
  return {};
}

// The walk fixture's head and hands at 90 Hz, without noise, written as "t_ns role x y z qx qy qz qw".
inline std::vector<TrackerSample> write_poses(const fs::path& file) {
  SimOptions sim;
  sim.position_noise_mm = 0;
  sim.rotation_noise_deg = 0;
  sim.dropout_rate_hz = 0;
  const std::vector<TrackerSample> samples = simulate_trackers(read_bvh(fixtures() / "walk_60.bvh"), sim);
  std::ofstream out(file);
  out.precision(9);
  for (const TrackerSample& s : samples) {
    if (!s.valid) continue;
    out << s.t_ns << ' ' << role_name(s.role) << ' ' << s.position_m.x() << ' ' << s.position_m.y() << ' '
        << s.position_m.z() << ' ' << s.rotation.x() << ' ' << s.rotation.y() << ' ' << s.rotation.z() << ' '
        << s.rotation.w() << '\n';
  }
  return samples;
}

inline std::vector<nlohmann::json> read_jsonl(const fs::path& file) {
  std::vector<nlohmann::json> lines;
  std::ifstream in(file);
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

inline Vec3 vec3(const nlohmann::json& a) { return Vec3(a[0].get<double>(), a[1].get<double>(), a[2].get<double>()); }
inline Quat quat_xyzw(const nlohmann::json& a) {
  return Quat(a[3].get<double>(), a[0].get<double>(), a[1].get<double>(), a[2].get<double>()).normalized();
}
inline Vec3 vec3(const std::array<float, 3>& a) { return Vec3(a[0], a[1], a[2]); }
inline Quat quat_xyzw(const std::array<float, 4>& a) { return Quat(a[3], a[0], a[1], a[2]).normalized(); }
inline double angle_deg(const Quat& a, const Quat& b) { return a.angularDistance(b) * 180.0 / M_PI; }

using test::collect;
using test::collect_until_quiet;

inline std::size_t joint_index(const protocol::SkeletonMessage& skeleton, const std::string& name) {
  const auto it = std::find(skeleton.names.begin(), skeleton.names.end(), name);
  EXPECT_NE(it, skeleton.names.end()) << name;
  return static_cast<std::size_t>(it - skeleton.names.begin());
}

}  // namespace bodyd::test::slimevr
