// `--output vmc:` (bodyd/io/vmc/vmc.h, docs/outputs.md "VMC"): the bundle's bytes read back by
// an OSC reader written here from the OSC 1.0 specification; and bodyd end to end, its bundles
// received by osc.js (tests/daemon/node/vmc_receive.js), forward kinematics over the Unity
// humanoid from the received local rotations compared with the ZeroMQ stream's joints.
#include "bodyd/daemon/config.h"
#include "bodyd/io/vmc/vmc.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/humanoid.h"
#include "bodyd/motion/tracker_log.h"
#include "../test_paths.h"
#include "zmq_helpers.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <bit>
#include <cstring>
#include <fstream>
#include <map>
#include <optional>
#include <thread>

namespace bodyd {
namespace {

// ---- A small OSC 1.0 reader (opensoundcontrol.org/spec-1_0): big-endian int32/float32,
// strings NUL-terminated and padded to 4 bytes, bundles "#bundle" + time tag + sized elements.

struct OscMessage {
  std::string address, types;
  std::vector<std::string> strings;
  std::vector<float> floats;
  std::vector<std::int32_t> ints;
};

struct OscReader {
  const std::vector<std::uint8_t>& b;
  std::size_t pos = 0;
  bool ok = true;

  std::uint32_t u32() {
    if (pos + 4 > b.size()) {
      ok = false;
      return 0;
    }
    const std::uint32_t v = (std::uint32_t(b[pos]) << 24) | (std::uint32_t(b[pos + 1]) << 16) |
                            (std::uint32_t(b[pos + 2]) << 8) | std::uint32_t(b[pos + 3]);
    pos += 4;
    return v;
  }
  std::string str() {
    std::string s;
    while (pos < b.size() && b[pos] != 0) s += static_cast<char>(b[pos++]);
    if (pos >= b.size()) {
      ok = false;
      return s;
    }
    pos += 4 - (s.size() % 4);  // the NUL and the padding
    return s;
  }
};

// The messages of one bundle, and its time tag. nullopt if the bytes are not a well-formed bundle.
std::optional<std::pair<std::uint64_t, std::vector<OscMessage>>> read_bundle(const std::vector<std::uint8_t>& bytes) {
  OscReader r{bytes};
  if (r.str() != "#bundle" || !r.ok) return std::nullopt;
  const std::uint64_t hi = r.u32(), lo = r.u32();
  std::vector<OscMessage> messages;
  while (r.ok && r.pos < bytes.size()) {
    const std::size_t size = r.u32();
    const std::size_t end = r.pos + size;
    if (end > bytes.size() || size % 4 != 0) return std::nullopt;
    OscMessage m;
    m.address = r.str();
    m.types = r.str();
    if (m.types.empty() || m.types[0] != ',') return std::nullopt;
    for (char t : m.types.substr(1)) {
      if (t == 's') m.strings.push_back(r.str());
      else if (t == 'f') m.floats.push_back(std::bit_cast<float>(r.u32()));
      else if (t == 'i') m.ints.push_back(static_cast<std::int32_t>(r.u32()));
      else return std::nullopt;
    }
    if (!r.ok || r.pos != end) return std::nullopt;
    messages.push_back(std::move(m));
  }
  if (!r.ok) return std::nullopt;
  return std::make_pair((hi << 32) | lo, std::move(messages));
}

TEST(VmcBundle, HoldsTheDocumentedMessagesInOrder) {
  UnityPose pose;
  for (std::size_t b = 0; b < kHumanoidBones.size(); ++b) {
    const double k = static_cast<double>(b);
    pose.local_positions[b] = Vec3(0.5 + k, -0.25 * k, 1e-3 * k);
    pose.local_rotations[b] = Quat(Eigen::AngleAxisd(0.1 * k, Vec3(1, -2, 3).normalized()));
  }
  daemon::vmc::BundleEncoder encoder;
  (void)encoder.encode(UnityPose{}, 99.0f);  // values of an earlier pose must all be overwritten
  const std::vector<std::uint8_t> bytes = encoder.encode(pose, 12.5f);
  const auto bundle = read_bundle(bytes);
  ASSERT_TRUE(bundle) << "not a well-formed OSC bundle";
  EXPECT_EQ(bundle->first, 1u) << "time tag: immediately";
  const auto& m = bundle->second;
  ASSERT_EQ(m.size(), daemon::vmc::kMessagesPerBundle);
  EXPECT_EQ(m[0].address, "/VMC/Ext/OK");
  EXPECT_EQ(m[0].types, ",i");
  EXPECT_EQ(m[0].ints, std::vector<std::int32_t>{1});
  EXPECT_EQ(m[1].address, "/VMC/Ext/T");
  EXPECT_EQ(m[1].types, ",f");
  EXPECT_EQ(m[1].floats, std::vector<float>{12.5f});
  EXPECT_EQ(m[2].address, "/VMC/Ext/Root/Pos");
  EXPECT_EQ(m[2].types, ",sfffffff");
  EXPECT_EQ(m[2].strings, std::vector<std::string>{"root"});
  EXPECT_EQ(m[2].floats, (std::vector<float>{0, 0, 0, 0, 0, 0, 1}));
  for (std::size_t b = 0; b < kHumanoidBones.size(); ++b) {
    const OscMessage& bone = m[3 + b];
    EXPECT_EQ(bone.address, "/VMC/Ext/Bone/Pos");
    EXPECT_EQ(bone.types, ",sfffffff");
    ASSERT_EQ(bone.strings.size(), 1u);
    EXPECT_EQ(bone.strings[0], kHumanoidBones[b].unity);
    const Vec3& p = pose.local_positions[b];
    const Quat& q = pose.local_rotations[b];
    EXPECT_EQ(bone.floats, (std::vector<float>{float(p.x()), float(p.y()), float(p.z()), float(q.x()), float(q.y()),
                                               float(q.z()), float(q.w())}))
        << bone.strings[0];
  }
  // The Unity names are the HumanBodyBones names the VMC protocol uses.
  EXPECT_EQ(m[3 + 5].strings[0], "LeftShoulder");
  EXPECT_EQ(m[3 + 20].strings[0], "RightToes");
}

// ---- End to end -----------------------------------------------------------------------------

const std::string kBodyd = (test::bin_dir() / "bodyd").string();

std::string node_missing() {
  if (std::system("node --version > /dev/null 2>&1") != 0) return "node is not installed (scripts/setup installs it)";
  if (!std::filesystem::exists(test::source_dir() / "tests/node/node_modules/osc/package.json"))
    return "the npm package osc is not installed in tests/node (scripts/setup runs npm ci there)";
  return {};
}

// One received bundle: the time and, per Unity bone name, position and rotation (x, y, z, w).
struct VmcFrame {
  double t_s = 0;
  std::map<std::string, std::array<double, 7>> bones;
  bool ok = false, root_identity = false;
};

VmcFrame parse_frame(const nlohmann::json& line) {
  VmcFrame f;
  if (!line.contains("packets")) return f;
  bool seen_ok = false;
  for (const auto& p : line["packets"]) {
    const std::string address = p["address"];
    const auto& args = p["args"];
    if (address == "/VMC/Ext/OK") seen_ok = args.size() == 1 && args[0]["type"] == "i" && args[0]["value"] == 1;
    if (address == "/VMC/Ext/T") f.t_s = args[0]["value"];
    if (address == "/VMC/Ext/Root/Pos" || address == "/VMC/Ext/Bone/Pos") {
      if (args.size() != 8 || args[0]["type"] != "s") return f;
      std::array<double, 7> v{};
      for (std::size_t k = 0; k < 7; ++k) {
        if (args[k + 1]["type"] != "f") return f;
        v[k] = args[k + 1]["value"];
      }
      if (address == "/VMC/Ext/Root/Pos")
        f.root_identity = args[0]["value"] == "root" && v == std::array<double, 7>{0, 0, 0, 0, 0, 0, 1};
      else
        f.bones[args[0]["value"]] = v;
    }
  }
  f.ok = seen_ok;
  return f;
}

TEST(VmcOutput, ForwardKinematicsOfTheReceivedBonesGivesTheStreamsJoints) {
  if (std::string why = node_missing(); !why.empty()) GTEST_SKIP() << why;
  test::TempDir dir;
  // 1.7 s of the bundled recording, paced (UDP to a Node receiver: a fast replay would only
  // measure how many datagrams the socket buffer holds).
  auto samples = read_tracker_log(daemon::bundled_recording_path()).samples;
  samples.resize(std::min<std::size_t>(samples.size(), 450));
  write_tracker_log(dir.path / "log.csv", samples);

  const auto port_file = dir.path / "port", out_file = dir.path / "vmc.jsonl";
  test::Child node({"/bin/sh", "-c",
                    "NODE_PATH='" + (test::source_dir() / "tests/node/node_modules").string() + "' exec node '" +
                        (test::source_dir() / "tests/daemon/node/vmc_receive.js").string() + "' '" +
                        port_file.string() + "' '" + out_file.string() + "'"},
                   dir.path / "node.txt");
  for (int i = 0; i < 1000 && !std::filesystem::exists(port_file); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(std::filesystem::exists(port_file)) << node.log();
  std::string port;
  std::ifstream(port_file) >> port;

  const auto endpoints_file = dir.path / "endpoints.json";
  test::Child bodyd({kBodyd, "--method", "ik", "--replay", (dir.path / "log.csv").string(), "--pub", "tcp://127.0.0.1:0",
                     "--control", "tcp://127.0.0.1:*", "--exit-at-end", "--wait-for-subscriber", "--send-hwm", "100000",
                     "--endpoints-file", endpoints_file.string(), "--output", "vmc:127.0.0.1:" + port},
                    dir.path / "bodyd.txt");
  const auto endpoints = test::wait_endpoints(endpoints_file, 10000);
  ASSERT_TRUE(endpoints) << bodyd.log();
  zmq::context_t ctx;
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, 0);
  sub.set(zmq::sockopt::subscribe, "pose");
  sub.connect(std::string((*endpoints)["pub"]));
  std::vector<protocol::PoseMessage> poses;
  // A reset a third of the way in (issue 45 item 3): a VMC receiver draws bodyd's avatar itself,
  // so the output publishes in the user's re-centred space, as the pose stream does: every bundle
  // still equals a ZeroMQ pose after it.
  bool recentred = false;
  while (auto pose = test::recv_pose(sub, poses.empty() ? 10000 : 2000)) {
    poses.push_back(*pose);
    if (poses.size() == 50) {
      const auto reset = test::control_request(ctx, (*endpoints)["control"], R"({"cmd":"reset"})");
      recentred = reset && (*reset)["ok"] == true;
    }
  }
  EXPECT_TRUE(recentred);
  ASSERT_EQ(bodyd.wait(5000), 0) << bodyd.log();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the last datagrams
  node.signal(SIGTERM);
  ASSERT_EQ(node.wait(5000), 0) << node.log();
  ASSERT_GT(poses.size(), 100u) << bodyd.log();

  // The rig of the daemon's skeleton, as a receiver would build it from the documented T-pose.
  std::string error;
  const Skeleton skeleton = read_bvh(daemon::bundled_skeleton_path()).skeleton;
  UnityRig rig;
  ASSERT_TRUE(make_unity_rig(skeleton, rig, error)) << error;

  std::vector<VmcFrame> frames;
  std::ifstream in(out_file);
  for (std::string line; std::getline(in, line);) frames.push_back(parse_frame(nlohmann::json::parse(line)));
  // UDP on loopback at 90 Hz: nothing should be lost, but the test needs only most of them.
  ASSERT_GE(frames.size(), poses.size() * 9 / 10) << "bundles received: " << frames.size() << ", poses: " << poses.size();

  std::size_t matched = 0;
  double worst_m = 0.0;
  std::optional<std::pair<double, std::int64_t>> first;  // (vmc t_s, pose t_ns) of the first match
  for (const VmcFrame& f : frames) {
    ASSERT_TRUE(f.ok) << "a bundle without /VMC/Ext/OK 1 or with malformed messages";
    ASSERT_TRUE(f.root_identity);
    ASSERT_EQ(f.bones.size(), kHumanoidBones.size());
    // Forward kinematics over the Unity hierarchy from the received local positions and rotations.
    UnityPose u;
    for (std::size_t b = 0; b < kHumanoidBones.size(); ++b) {
      const auto& v = f.bones.at(std::string(kHumanoidBones[b].unity));
      u.local_positions[b] = Vec3(v[0], v[1], v[2]);
      u.local_rotations[b] = Quat(v[6], v[3], v[4], v[5]).normalized();
    }
    std::array<Vec3, kHumanoidBones.size()> p;
    std::array<Quat, kHumanoidBones.size()> q;
    unity_forward_kinematics(rig, u, p, q);
    // The pose with the same Hips position (both are the same float32 values, z negated).
    const protocol::PoseMessage* pose = nullptr;
    for (const auto& candidate : poses) {
      const auto& h = candidate.joints[static_cast<std::size_t>(rig.joint[0])].position_m;
      if (h[0] == float(u.local_positions[0].x()) && h[1] == float(u.local_positions[0].y()) &&
          h[2] == float(-u.local_positions[0].z()))
        pose = &candidate;
    }
    if (pose == nullptr) continue;  // sent before the subscriber joined (cannot happen with --wait-for-subscriber)
    ++matched;
    for (std::size_t b = 0; b < kHumanoidBones.size(); ++b) {
      const auto& j = pose->joints[static_cast<std::size_t>(rig.joint[b])].position_m;
      const double e = (unity_from_bodyd(p[b]) - Vec3(j[0], j[1], j[2])).norm();
      worst_m = std::max(worst_m, e);
      EXPECT_LE(e, 1e-3) << kHumanoidBones[b].unity << " at t_ns " << pose->t_ns;
    }
    // /VMC/Ext/T counts the seconds of pose time.
    if (!first) first = {f.t_s, pose->t_ns};
    EXPECT_NEAR(f.t_s - first->first, static_cast<double>(pose->t_ns - first->second) * 1e-9, 1e-4);
  }
  EXPECT_GE(matched, frames.size() * 9 / 10);
  RecordProperty("bundles_received", static_cast<int>(frames.size()));
  RecordProperty("poses_on_zmq", static_cast<int>(poses.size()));
  RecordProperty("bundles_matched", static_cast<int>(matched));
  RecordProperty("worst_joint_error_mm", std::to_string(worst_m * 1e3));
}

}  // namespace
}  // namespace bodyd
