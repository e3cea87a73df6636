// Network inputs (vrchat:, vmc:, udp:): the pure decoders with packets built by liblo, the
// Unity axis conversions against matrices written out here, every malformed-packet kind,
// VMC's automatic role assignment, OSCQuery over HTTP (Node's http module), and the
// "same samples, same poses" check of VMC and UDP input against a tracker-log replay
// (Node's osc.js as the sender).
#include "bodyd/io/osc/network_source.h"
#include "bodyd/io/open_source.h"
#include "bodyd/inference/ik.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/tracker_log.h"
#include "bodyd/simulators/tracker_sim.h"

#include "../../io/vrchat/oscquery.h"
#include "../../io/vmc/vmc_roles.h"
#include "../test_paths.h"
#include "osc_helpers.h"

#include "bodyd/test/log_capture.h"
#include "bodyd/test/sinks.h"
#include "bodyd/test/temp_dir.h"
#include "bodyd/test/wait.h"

#include <gtest/gtest.h>
#include <lo/lo.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <mutex>
#include <sstream>
#include <thread>

namespace bodyd::drivers {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

// ---- packets built by liblo -------------------------------------------------------------------
using test::osc_floats;
using test::osc_serialise;
using test::osc_vmc;

// A bundle of the given (path, message-builder) pairs; liblo owns the messages until freed.
Bytes bundle(const std::vector<std::pair<const char*, lo_message>>& messages) {
  lo_bundle b = lo_bundle_new(LO_TT_IMMEDIATE);
  for (const auto& [path, m] : messages) lo_bundle_add_message(b, path, m);
  std::size_t n = 0;
  void* data = lo_bundle_serialise(b, nullptr, &n);
  Bytes out(static_cast<std::uint8_t*>(data), static_cast<std::uint8_t*>(data) + n);
  std::free(data);
  lo_bundle_free_recursive(b);
  return out;
}

lo_message pose_lo(std::initializer_list<float> values) {
  lo_message m = lo_message_new();
  for (float v : values) lo_message_add_float(m, v);
  return m;
}

using test::wrap_in_bundle;

InputReject decode(const Bytes& b, std::vector<OscMessage>& out) {
  std::string detail;
  const InputReject r = decode_osc_packet(b.data(), b.size(), out, detail);
  if (r != InputReject::None) {
    EXPECT_FALSE(detail.empty());
  }
  return r;
}

// ---- sockets, sinks, waiting ---------------------------------------------------------------------
using CaptureSink = test::CollectingSink;

class UdpSender {
 public:
  explicit UdpSender(int port) : fd_(socket(AF_INET, SOCK_DGRAM, 0)) {
    to_.sin_family = AF_INET;
    to_.sin_port = htons(static_cast<std::uint16_t>(port));
    to_.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  }
  ~UdpSender() { close(fd_); }
  void send(const Bytes& b) const {
    ASSERT_EQ(sendto(fd_, b.data(), b.size(), 0, reinterpret_cast<const sockaddr*>(&to_), sizeof to_),
              static_cast<ssize_t>(b.size()));
  }
  void send(std::string_view text) const { send(Bytes(text.begin(), text.end())); }

 private:
  int fd_;
  sockaddr_in to_{};
};

bool wait_for(const std::function<bool()>& done, int timeout_ms = 5000) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

std::unique_ptr<NetworkSource> open_test_source(NetworkKind kind, std::map<std::string, Role> vmc_roles = {}) {
  NetworkSourceOptions o;
  o.kind = kind;
  o.name = kind == NetworkKind::Vrchat ? "vrchat:test" : kind == NetworkKind::Vmc ? "vmc:test" : "udp:test";
  o.port = 0;
  o.oscquery = false;
  o.vmc_roles = std::move(vmc_roles);
  std::string error;
  auto s = open_network_source(o, error);
  EXPECT_TRUE(s) << error;
  return s;
}

// open_test_source, started into `sink` as source 0; nullptr (a test failure) when it did not
// open or start.
std::unique_ptr<NetworkSource> start_test_source(NetworkKind kind, CaptureSink& sink,
                                                 std::map<std::string, Role> vmc_roles = {}) {
  auto s = open_test_source(kind, std::move(vmc_roles));
  if (!s) return nullptr;
  if (const std::string error = s->start(sink, 0); !error.empty()) {
    ADD_FAILURE() << "start: " << error;
    return nullptr;
  }
  return s;
}

// ---- Node ---------------------------------------------------------------------------------------
// Runs `node SCRIPT ARGS...` with the osc.js package on NODE_PATH; empty `why_not` when it ran.
struct NodeRun {
  int exit_code = -1;
  std::string out;
};
std::string node_missing() {
  if (std::system("node --version > /dev/null 2>&1") != 0) return "node is not installed (scripts/setup installs it)";
  if (!fs::exists(test::source_dir() / "tests/node/node_modules/osc/package.json"))
    return "the npm package osc is not installed in tests/node (scripts/setup runs npm ci there)";
  return {};
}
NodeRun run_node(const std::string& script, const std::string& args) {
  const std::string command = "NODE_PATH='" + (test::source_dir() / "tests/node/node_modules").string() + "' node '" +
                              (test::source_dir() / "tests/drivers/node" / script).string() + "' " + args + " 2>&1";
  NodeRun r;
  FILE* p = popen(command.c_str(), "r");
  if (!p) return r;
  char buffer[4096];
  std::size_t n;
  while ((n = fread(buffer, 1, sizeof buffer, p)) > 0) r.out.append(buffer, n);
  const int status = pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// =============================================================================================
TEST(OscDecode, VrchatMessageAndBundles) {
  std::vector<OscMessage> out;
  ASSERT_EQ(decode(osc_floats("/tracking/vrsystem/head/pose", {0.1f, 1.6f, 0.2f, 10, 20, 30}), out),
            InputReject::None);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].address, "/tracking/vrsystem/head/pose");
  EXPECT_EQ(out[0].type_tags, "ffffff");
  VrchatPose pose;
  InputReject why;
  ASSERT_EQ(decode_vrchat_message(out[0], pose, why), MessageUse::Use);
  EXPECT_EQ(pose.role, Role::Head);
  EXPECT_EQ(pose.position_unity[1], static_cast<double>(1.6f));
  EXPECT_EQ(pose.euler_deg_unity[2], 30.0);

  // A bundle of three (as a sender may group them), and a bundle inside a bundle.
  const Bytes three = bundle({{"/tracking/vrsystem/head/pose", pose_lo({0, 1.6f, 0, 0, 0, 0})},
                              {"/tracking/vrsystem/leftwrist/pose", pose_lo({-0.3f, 1, 0, 0, 0, 0})},
                              {"/tracking/vrsystem/rightwrist/pose", pose_lo({0.3f, 1, 0, 0, 0, 0})}});
  ASSERT_EQ(decode(three, out), InputReject::None);
  ASSERT_EQ(out.size(), 3u);
  const std::array<Role, 3> roles{Role::Head, Role::LeftHand, Role::RightHand};
  for (int i = 0; i < 3; ++i) {
    ASSERT_EQ(decode_vrchat_message(out[i], pose, why), MessageUse::Use);
    EXPECT_EQ(pose.role, roles[i]);
  }
  ASSERT_EQ(decode(wrap_in_bundle({three, osc_floats("/avatar/parameters/x", {1})}), out), InputReject::None);
  EXPECT_EQ(out.size(), 4u);
  // Other VRChat traffic is ignored, not rejected.
  EXPECT_EQ(decode_vrchat_message(out[3], pose, why), MessageUse::Ignore);
  ASSERT_EQ(decode(osc_floats("/tracking/vrsystem/hip/pose", {0, 0, 0, 0, 0, 0}), out), InputReject::None);
  EXPECT_EQ(decode_vrchat_message(out[0], pose, why), MessageUse::Ignore);
}

TEST(OscDecode, VmcMessage) {
  std::vector<OscMessage> out;
  ASSERT_EQ(decode(osc_vmc("/VMC/Ext/Con/Pos", "LHR-1", {0.5f, 1, 2, 0, 0, 0, 1}), out), InputReject::None);
  VmcPose pose;
  InputReject why;
  ASSERT_EQ(decode_vmc_message(out[0], pose, why), MessageUse::Use);
  EXPECT_EQ(pose.device, VmcDevice::Controller);
  EXPECT_EQ(pose.serial, "LHR-1");
  EXPECT_EQ(pose.position_m, Vec3(0.5, 1, -2));  // Unity z forward -> bodyd -z
  ASSERT_EQ(decode(osc_vmc("/VMC/Ext/Bone/Pos", "Hips", {0, 1, 0, 0, 0, 0, 1}), out), InputReject::None);
  EXPECT_EQ(decode_vmc_message(out[0], pose, why), MessageUse::Ignore);
}

// Every malformed kind, with the reason it must be counted under.
struct BadPacket {
  const char* what;
  Bytes bytes;
  InputReject expected;
};

std::vector<BadPacket> bad_vrchat_packets() {
  const Bytes good = osc_floats("/tracking/vrsystem/head/pose", {0, 1.6f, 0, 0, 0, 0});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<BadPacket> bad;
  bad.push_back({"truncated message", Bytes(good.begin(), good.end() - 6), InputReject::Truncated});
  bad.push_back({"empty datagram", Bytes{}, InputReject::Truncated});
  Bytes bad_bundle = wrap_in_bundle({good});
  bad_bundle[19] = 0xF0;  // element size far beyond the datagram
  bad.push_back({"bundle element past the end", bad_bundle, InputReject::Truncated});
  bad.push_back({"not OSC", Bytes{'h', 'e', 'l', 'l', 'o', 0, 0, 0}, InputReject::NotOsc});
  {
    lo_message m = lo_message_new();
    for (int i = 0; i < 5; ++i) lo_message_add_float(m, 0);
    lo_message_add_int32(m, 7);
    bad.push_back({"wrong type tags", osc_serialise(m, "/tracking/vrsystem/head/pose"), InputReject::BadTypeTags});
  }
  bad.push_back({"wrong argument count", osc_floats("/tracking/vrsystem/head/pose", {0, 1.6f, 0, 0, 0}),
                 InputReject::WrongArgCount});
  bad.push_back({"NaN position", osc_floats("/tracking/vrsystem/head/pose", {nan, 1.6f, 0, 0, 0, 0}),
                 InputReject::NonFinite});
  bad.push_back({"infinite angle", osc_floats("/tracking/vrsystem/leftwrist/pose", {0, 1, 0, 0, inf, 0}),
                 InputReject::NonFinite});
  bad.push_back({"absurd position", osc_floats("/tracking/vrsystem/rightwrist/pose", {0, 1e6f, 0, 0, 0, 0}),
                 InputReject::AbsurdValue});
  bad.push_back({"absurd angle", osc_floats("/tracking/vrsystem/head/pose", {0, 1.6f, 0, 1e7f, 0, 0}),
                 InputReject::AbsurdValue});
  std::vector<Bytes> many(600, good);
  bad.push_back({"600 messages in one bundle", wrap_in_bundle(many), InputReject::Oversized});
  Bytes nested = good;
  for (int i = 0; i < 6; ++i) nested = wrap_in_bundle({nested});
  bad.push_back({"bundles nested 6 deep", nested, InputReject::Oversized});
  bad.push_back({"40000-byte datagram", Bytes(40000, '/'), InputReject::Oversized});
  return bad;
}

TEST(OscDecode, EveryMalformedKindIsRejectedWithItsReason) {
  for (const BadPacket& b : bad_vrchat_packets()) {
    SCOPED_TRACE(b.what);
    std::vector<OscMessage> out;
    std::string detail;
    InputReject r = decode_osc_packet(b.bytes.data(), b.bytes.size(), out, detail);
    if (r == InputReject::None) {  // structurally fine: the VRChat decoder must reject it
      ASSERT_EQ(out.size(), 1u);
      VrchatPose pose;
      EXPECT_EQ(decode_vrchat_message(out[0], pose, r), MessageUse::Reject);
    } else {
      EXPECT_TRUE(out.empty());
    }
    EXPECT_EQ(input_reject_name(r), input_reject_name(b.expected));
  }
  // VMC: a quaternion far from unit length, a number where the serial goes.
  std::vector<OscMessage> out;
  VmcPose pose;
  InputReject why;
  ASSERT_EQ(decode(osc_vmc("/VMC/Ext/Hmd/Pos", "H", {0, 1.6f, 0, 0, 0, 0, 0}), out), InputReject::None);
  EXPECT_EQ(decode_vmc_message(out[0], pose, why), MessageUse::Reject);
  EXPECT_EQ(why, InputReject::AbsurdValue);
  ASSERT_EQ(decode(osc_floats("/VMC/Ext/Hmd/Pos", {0, 0, 1.6f, 0, 0, 0, 0, 1}), out), InputReject::None);
  EXPECT_EQ(decode_vmc_message(out[0], pose, why), MessageUse::Reject);
  EXPECT_EQ(why, InputReject::BadTypeTags);
}

TEST(TrackerLineDecode, AcceptsLogLinesAndRejectsTheRest) {
  TrackerSample s;
  std::int64_t sender_t = 0;
  InputReject why;
  std::string detail;
  const std::string line = "123456789,left_hand,1,0.25,1.5,-0.5,0,0,0,1\n";
  ASSERT_EQ(decode_tracker_line(reinterpret_cast<const std::uint8_t*>(line.data()), line.size(), s, sender_t, why,
                                detail),
            MessageUse::Use)
      << detail;
  EXPECT_EQ(sender_t, 123456789);
  EXPECT_EQ(s.role, Role::LeftHand);
  EXPECT_EQ(s.position_m, Vec3(0.25, 1.5, -0.5));
  for (const std::string ignored : {"# bodyd-tracker-log v1", "t_ns,role,valid,px,py,pz,qx,qy,qz,qw"})
    EXPECT_EQ(decode_tracker_line(reinterpret_cast<const std::uint8_t*>(ignored.data()), ignored.size(), s, sender_t,
                                  why, detail),
              MessageUse::Ignore);
  const std::pair<std::string, InputReject> bad[] = {
      {"1,head,1,0,1.6,0,0,0,0", InputReject::BadLine},                           // 9 fields
      {"1,tail,1,0,1.6,0,0,0,0,1", InputReject::BadLine},                         // unknown role
      {"1,head,1,nan,1.6,0,0,0,0,1", InputReject::BadLine},                       // non-finite (the log reader's wall)
      {"1,head,1,0,1.6,0,0,0,0,1\n2,head,1,0,1.6,0,0,0,0,1", InputReject::BadLine},  // two lines
      {std::string(2000, '1'), InputReject::Oversized},
  };
  for (const auto& [text, expected] : bad) {
    SCOPED_TRACE(text.substr(0, 60));
    EXPECT_EQ(decode_tracker_line(reinterpret_cast<const std::uint8_t*>(text.data()), text.size(), s, sender_t, why,
                                  detail),
              MessageUse::Reject);
    EXPECT_EQ(why, expected);
  }
}

// ---- Unity's axes -------------------------------------------------------------------------------
// Rotation matrices written out (column vectors), independent of rotation.h and Eigen's AngleAxis.
Mat3 rx(double deg) {
  const double a = deg * M_PI / 180, c = std::cos(a), s = std::sin(a);
  return (Mat3() << 1, 0, 0, 0, c, -s, 0, s, c).finished();
}
Mat3 ry(double deg) {
  const double a = deg * M_PI / 180, c = std::cos(a), s = std::sin(a);
  return (Mat3() << c, 0, s, 0, 1, 0, -s, 0, c).finished();
}
Mat3 rz(double deg) {
  const double a = deg * M_PI / 180, c = std::cos(a), s = std::sin(a);
  return (Mat3() << c, -s, 0, s, c, 0, 0, 0, 1).finished();
}

TEST(UnityAxes, EulerOrderAndMirror) {
  const Mat3 S = Vec3(1, 1, -1).asDiagonal();
  // Quaternion.Euler(0, 90, 0) turns Unity's forward (+z) to its right (+x); in bodyd's axes
  // forward is -z: the converted rotation must turn (0, 0, -1) to (1, 0, 0).
  const Quat yaw = unity_rotation_to_bodyd(unity_euler_deg_to_quat(0, 90, 0));
  EXPECT_LT((yaw * Vec3(0, 0, -1) - Vec3(1, 0, 0)).norm(), 1e-12);
  // Z first, then X, then Y: Euler(90, 90, 0) takes up (0, 1, 0) to (0, 0, 1) by X, then to
  // (1, 0, 0) by Y. (Y first, then X, would end at (0, 0, 1).)
  const Quat q = unity_euler_deg_to_quat(90, 90, 0);
  EXPECT_LT((q * Vec3(0, 1, 0) - Vec3(1, 0, 0)).norm(), 1e-12);
  // General angles against the written-out product, and the mirror law S R S in bodyd's axes.
  for (const Vec3& e : {Vec3(30, 45, 60), Vec3(-170, 10, 95), Vec3(359, 181, 0.5), Vec3(89.9, -45, 270)}) {
    const Mat3 unity = ry(e.y()) * rx(e.x()) * rz(e.z());
    const Quat q_unity = unity_euler_deg_to_quat(e.x(), e.y(), e.z());
    EXPECT_LT((q_unity.toRotationMatrix() - unity).norm(), 1e-12) << e.transpose();
    const Quat q_bodyd = unity_rotation_to_bodyd(q_unity);
    EXPECT_LT((q_bodyd.toRotationMatrix() - S * unity * S).norm(), 1e-12) << e.transpose();
    EXPECT_NEAR(q_bodyd.norm(), 1.0, 1e-12);
    // The conversion is its own inverse.
    EXPECT_TRUE(unity_rotation_to_bodyd(q_bodyd).coeffs() == q_unity.coeffs());
    // A point moved in Unity, then converted = converted, then moved in bodyd.
    const Vec3 v(0.3, -1.2, 2.5);
    EXPECT_LT((unity_position_to_bodyd(unity * v) - q_bodyd * unity_position_to_bodyd(v)).norm(), 1e-12);
  }
  EXPECT_EQ(unity_position_to_bodyd(Vec3(1, 2, 3)), Vec3(1, 2, -3));
}

// ---- specs and binding ----------------------------------------------------------------------------
TEST(NetworkSpec, DefaultsOptionsAndErrors) {
  std::string error;
  auto v = parse_network_spec(NetworkKind::Vrchat, "vrchat:", "", error);
  ASSERT_TRUE(v) << error;
  EXPECT_EQ(v->host, "127.0.0.1");
  EXPECT_EQ(v->port, 9001);
  EXPECT_TRUE(v->oscquery);
  v = parse_network_spec(NetworkKind::Vrchat, "vrchat:9100?oscquery=off", "9100?oscquery=off", error);
  ASSERT_TRUE(v) << error;
  EXPECT_EQ(v->port, 9100);
  EXPECT_FALSE(v->oscquery);
  auto m = parse_network_spec(NetworkKind::Vmc, "vmc:0.0.0.0:39540?head=HMD&left_hand=LHR-A",
                              "0.0.0.0:39540?head=HMD&left_hand=LHR-A", error);
  ASSERT_TRUE(m) << error;
  EXPECT_EQ(m->host, "0.0.0.0");
  EXPECT_EQ(m->port, 39540);
  EXPECT_EQ(m->vmc_roles.at("HMD"), Role::Head);
  EXPECT_EQ(m->vmc_roles.at("LHR-A"), Role::LeftHand);
  EXPECT_EQ(parse_network_spec(NetworkKind::Vmc, "vmc:", "", error)->port, 39539);
  EXPECT_FALSE(parse_network_spec(NetworkKind::Udp, "udp:", "", error));
  EXPECT_NE(error.find("missing the port"), std::string::npos);
  EXPECT_FALSE(parse_network_spec(NetworkKind::Udp, "udp:70000", "70000", error));
  EXPECT_FALSE(parse_network_spec(NetworkKind::Vmc, "vmc:1?tail=X", "1?tail=X", error));
  EXPECT_NE(error.find("unknown option"), std::string::npos);
  // Through open_source: the spec kinds are registered.
  SourceOptions options;
  EXPECT_TRUE(parse_source_spec("vrchat:", error));
  EXPECT_FALSE(open_source("udp:not-a-port", options, error));
  EXPECT_NE(error.find("not a UDP port"), std::string::npos) << error;
}

TEST(NetworkSpec, NonLoopbackNeedsAllowRemote) {
  SourceOptions options;
  std::string error;
  EXPECT_FALSE(open_source("udp:0.0.0.0:0", options, error));
  EXPECT_NE(error.find("--allow-remote"), std::string::npos) << error;
  EXPECT_NE(error.find("no authentication"), std::string::npos) << error;
  options.allow_remote = true;
  auto s = open_source("udp:0.0.0.0:0", options, error);
  EXPECT_TRUE(s) << error;
}

TEST(NetworkSpec, BusyPortIsReported) {
  auto first = open_test_source(NetworkKind::Udp);
  ASSERT_TRUE(first);
  SourceOptions options;
  std::string error;
  EXPECT_FALSE(open_source("udp:127.0.0.1:" + std::to_string(first->bound_port()), options, error));
  EXPECT_NE(error.find("another program"), std::string::npos) << error;
}

// ---- running sources --------------------------------------------------------------------------------
TEST(NetworkSource, MalformedPacketsAreCountedAndNeverReachTheSink) {
  auto source = open_test_source(NetworkKind::Vrchat);
  ASSERT_TRUE(source);
  CaptureSink sink;
  ASSERT_EQ(source->start(sink, 3), "");
  UdpSender sender(source->bound_port());
  const std::vector<BadPacket> bad = bad_vrchat_packets();
  const Bytes good = bundle({{"/tracking/vrsystem/head/pose", pose_lo({0, 1.6f, 0, 0, 180, 0})},
                             {"/tracking/vrsystem/leftwrist/pose", pose_lo({-0.3f, 1, -0.2f, 0, 0, 90})}});
  for (const BadPacket& b : bad) {
    sender.send(good);
    sender.send(b.bytes);
  }
  sender.send(osc_floats("/avatar/parameters/VRMode", {1}));  // other VRChat traffic
  const std::uint64_t datagrams = 2 * bad.size() + 1;
  ASSERT_TRUE(wait_for([&] { return source->stats().datagrams == datagrams; })) << source->stats().datagrams;
  source->stop();
  const NetworkStats st = source->stats();
  std::array<std::uint64_t, kInputRejectCount> expected{};
  for (const BadPacket& b : bad) ++expected[static_cast<int>(b.expected)];
  for (int i = 0; i < kInputRejectCount; ++i)
    EXPECT_EQ(st.rejected[i], expected[i]) << input_reject_name(static_cast<InputReject>(i));
  EXPECT_EQ(st.ignored, 1u);
  const SourceStatus status = source->status();
  EXPECT_EQ(status.rejected, bad.size());
  EXPECT_EQ(status.rejected_by_reason.at("oversized"), 3u);
  EXPECT_NE(status.last_error.find("rejected a packet from 127.0.0.1:"), std::string::npos) << status.last_error;
  // Only the good bundles' samples, hands before the head, stamped on arrival.
  const std::vector<SourceSample> samples = sink.samples();
  ASSERT_EQ(samples.size(), 2 * bad.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const SourceSample& s = samples[i];
    EXPECT_EQ(s.sample.role, i % 2 == 0 ? Role::LeftHand : Role::Head);
    EXPECT_TRUE(s.sample.position_m.allFinite());
    EXPECT_NEAR(s.sample.rotation.norm(), 1.0, 1e-12);
    EXPECT_EQ(s.sample.t_ns, s.arrival_ns);
    EXPECT_EQ(s.source_index, 3);
    EXPECT_FALSE(s.has_device_time);
  }
  // The head: Unity (0, 1.6, 0), yaw 180 -> bodyd (0, 1.6, -0) facing +z.
  EXPECT_LT((samples[1].sample.rotation * Vec3(0, 0, -1) - Vec3(0, 0, 1)).norm(), 1e-6);
  EXPECT_NEAR(samples[1].sample.position_m.y(), 1.6, 1e-6);
}

TEST(NetworkSource, VmcAssignsHandsByTheHeadsLeftAndRight) {
  for (const double head_yaw_deg : {0.0, 180.0}) {
    SCOPED_TRACE(head_yaw_deg);
    CaptureSink sink;
    auto source = start_test_source(NetworkKind::Vmc, sink);
    ASSERT_TRUE(source);
    UdpSender sender(source->bound_port());
    // Unity quaternion of a yaw about +y.
    const auto half = static_cast<float>(head_yaw_deg * M_PI / 360);
    // Controllers before the head: unassigned until the head is seen.
    sender.send(osc_vmc("/VMC/Ext/Con/Pos", "A", {0.3f, 1.0f, 0.2f, 0, 0, 0, 1}));
    sender.send(osc_vmc("/VMC/Ext/Hmd/Pos", "HMD", {0, 1.6f, 0, 0, std::sin(half), 0, std::cos(half)}));
    sender.send(osc_vmc("/VMC/Ext/Con/Pos", "B", {-0.3f, 1.0f, 0.2f, 0, 0, 0, 1}));
    sender.send(osc_vmc("/VMC/Ext/Con/Pos", "A", {0.3f, 1.0f, 0.2f, 0, 0, 0, 1}));
    sender.send(osc_vmc("/VMC/Ext/Tra/Pos", "T", {0, 0.1f, 0, 0, 0, 0, 1}));  // trackers: configured only
    ASSERT_TRUE(wait_for([&] { return source->stats().datagrams == 5; }));
    source->stop();
    const auto samples = sink.samples();
    ASSERT_EQ(samples.size(), 3u);
    EXPECT_EQ(samples[0].sample.role, Role::Head);
    // Unity +x is the head's right when it faces Unity +z (yaw 0): B (x = -0.3) is left.
    const Role role_of_b = head_yaw_deg == 0.0 ? Role::LeftHand : Role::RightHand;
    for (std::size_t i = 1; i < 3; ++i) {
      const bool is_b = samples[i].sample.position_m.x() < 0;
      EXPECT_EQ(samples[i].sample.role, is_b ? role_of_b : (role_of_b == Role::LeftHand ? Role::RightHand : Role::LeftHand));
    }
    EXPECT_EQ(source->stats().unassigned, 2u);  // the first "A" and the tracker
  }
}

TEST(NetworkSource, VmcConfiguredSerials) {
  CaptureSink sink;
  auto source = start_test_source(NetworkKind::Vmc, sink, {{"T1", Role::LeftHand}, {"C9", Role::RightHand}});
  ASSERT_TRUE(source);
  UdpSender sender(source->bound_port());
  sender.send(osc_vmc("/VMC/Ext/Tra/Pos", "T1", {0.3f, 1, 0, 0, 0, 0, 1}));
  sender.send(osc_vmc("/VMC/Ext/Con/Pos", "C9", {-0.3f, 1, 0, 0, 0, 0, 1}));
  ASSERT_TRUE(wait_for([&] { return sink.samples().size() == 2; }));
  source->stop();
  EXPECT_EQ(sink.samples()[0].sample.role, Role::LeftHand);
  EXPECT_EQ(sink.samples()[1].sample.role, Role::RightHand);
}

// ---- VMC roles (issue 20 item 2): times chosen by the test -------------------------------------------
VmcPose vmc_pose(VmcDevice device, const std::string& serial, double x_m, double y_m = 1.0) {
  VmcPose p;
  p.device = device;
  p.serial = serial;
  p.position_m = Vec3(x_m, y_m, 0);
  return p;
}

using test::LogCapture;

constexpr std::int64_t kFrameNs = 11'000'000;  // 90 Hz

TEST(VmcRoles, AStreamingHolderKeepsItsRoleAndASilentOneLosesIt) {
  const LogCapture log;
  detail::VmcRoles roles("vmc:test", {});
  constexpr std::int64_t kStale = detail::VmcRoles::kStaleNs;
  // One forged packet comes first and takes the head: nothing tells it from a headset yet.
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "FORGED", 5, 3), 0), Role::Head);
  // The real headset, streaming: unassigned while the forged serial's last pose is recent...
  std::int64_t t = kFrameNs;
  for (; t < kStale; t += kFrameNs) EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Hmd, "REAL", 0, 1.6), t)) << t;
  // ...and the head once the forged one has been silent for kStaleNs (before the fix: never).
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "REAL", 0, 1.6), t), Role::Head);
  // Now no newcomer takes it from the streaming headset, however often it sends.
  for (int i = 0; i < 300; ++i) {
    t += kFrameNs;
    EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "REAL", 0, 1.6), t), Role::Head);
    EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Hmd, "FORGED-2", 5, 3), t + 1));
  }
  EXPECT_EQ(roles.holder(Role::Head), "REAL");
  // The hands likewise: two controllers take them; a third one waits.
  EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Controller, "A", 0.3), t));
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "B", -0.3), t), Role::LeftHand);  // -x: the head's left
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "A", 0.3), t + 1), Role::RightHand);
  for (int i = 0; i < 100; ++i) {  // B is silent from now on
    t += kFrameNs;
    EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "A", 0.3), t), Role::RightHand);
    EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "REAL", 0, 1.6), t), Role::Head);
    if (i < 80) {  // B is recent
      EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Controller, "C", 0.4), t)) << i;
    }
  }
  // B has been silent for 100 frames (1.1 s): C takes the left hand; A keeps the right.
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "C", -0.4), t + kFrameNs), Role::LeftHand);
  EXPECT_EQ(roles.holder(Role::RightHand), "A");
  const std::string text = log.text();
  EXPECT_NE(text.find("serial \"FORGED\" sent nothing for 1.0 s: head is free"), std::string::npos) << text;
  EXPECT_NE(text.find("serial \"REAL\" is head (the next HMD after \"FORGED\" went silent"), std::string::npos) << text;
  EXPECT_NE(text.find("serial \"FORGED-2\" ignored: the head is held by \"REAL\""), std::string::npos) << text;
  // Refusals are logged at a limited rate: 300 refused packets, 9 lines (1st, 2nd, 4th, ... 256th).
  std::size_t lines = 0;
  for (std::size_t at = text.find("\"FORGED-2\" ignored"); at != std::string::npos; at = text.find("\"FORGED-2\" ignored", at + 1))
    ++lines;
  EXPECT_EQ(lines, 9u) << text;
}

// A forged first head facing backwards decides the hands' sides wrongly; when the real head
// takes over, the sides are decided again relative to it.
TEST(VmcRoles, HandsAreDecidedAgainForANewHead) {
  detail::VmcRoles roles("vmc:test", {});
  VmcPose forged = vmc_pose(VmcDevice::Hmd, "FORGED", 0, 1.6);
  forged.rotation = Quat(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));
  ASSERT_EQ(roles.role_of(forged, 0), Role::Head);
  EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Controller, "A", 0.3), 1));
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "B", -0.3), 2), Role::RightHand);  // relative to FORGED
  std::int64_t t = detail::VmcRoles::kStaleNs;
  ASSERT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "REAL", 0, 1.6), t), Role::Head);  // facing +z
  EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Controller, "A", 0.3), t + 1));  // waiting for both again
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "B", -0.3), t + 2), Role::LeftHand);
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "A", 0.3), t + 3), Role::RightHand);
}

TEST(VmcRoles, ConfiguredSerialsAreNeverTakenOrReleased) {
  detail::VmcRoles roles("vmc:test", {{"H", Role::Head}});
  EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Hmd, "OTHER", 0, 1.6), 0));
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "H", 0, 1.6), 1), Role::Head);
  // Silent for a long time: still the head's, and nobody else gets it.
  EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Hmd, "OTHER", 0, 1.6), 100 * detail::VmcRoles::kStaleNs));
  EXPECT_EQ(roles.holder(Role::Head), "H");
}

TEST(VmcRoles, SerialsBeyondTheLimitAreNotTrackedAndSilentOnesAreForgotten) {
  const LogCapture log;
  detail::VmcRoles roles("vmc:test", {});
  // Before any head: controllers wait as candidates; a flood of made-up serials is capped.
  for (int i = 0; i < 1000; ++i)
    EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Controller, "FAKE-" + std::to_string(i), 0.1), i));
  EXPECT_EQ(roles.candidates(), detail::VmcRoles::kMaxCandidates);
  const std::string text = log.text();
  EXPECT_NE(text.find("controller serial \"FAKE-16\" ignored: 16 controllers without a role are already waiting"),
            std::string::npos)
      << text;
  // Logged at a limited rate: 984 ignored, 10 lines (1st, 2nd, 4th, ... 512th).
  std::size_t lines = 0;
  for (std::size_t at = text.find("controllers without a role"); at != std::string::npos;
       at = text.find("controllers without a role", at + 1))
    ++lines;
  EXPECT_EQ(lines, 10u);
  // A second later the made-up ones are forgotten: the real devices get their roles.
  const std::int64_t t = 1000 + detail::VmcRoles::kStaleNs;
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "HMD", 0, 1.6), t), Role::Head);
  EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Controller, "R", 0.3), t + 1));
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "L", -0.3), t + 2), Role::LeftHand);
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Controller, "R", 0.3), t + 3), Role::RightHand);
  EXPECT_EQ(roles.candidates(), 0u);
}

// A serial is text from the network: escaped in every log line (as the udp: input's lines
// are, through printable()), so it can neither move the terminal nor forge a log line.
TEST(VmcRoles, SerialsAreEscapedInTheLog) {
  const LogCapture log;
  detail::VmcRoles roles("vmc:test", {});
  const std::string forged = "X\x1b[2J\n2026-12-02 00:00:00.000 bodyd critical: FAKE LINE";
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, forged, 0, 1.6), 0), Role::Head);
  EXPECT_FALSE(roles.role_of(vmc_pose(VmcDevice::Hmd, forged + "2", 0, 1.6), 1));
  EXPECT_EQ(roles.role_of(vmc_pose(VmcDevice::Hmd, "Y", 0, 1.6), 2 * detail::VmcRoles::kStaleNs), Role::Head);
  const std::string text = log.text();
  EXPECT_EQ(text.find('\x1b'), std::string::npos) << text;
  EXPECT_EQ(text.find("\n2026-12-02"), std::string::npos) << text;
  EXPECT_NE(text.find("serial \"X\\x1b[2J\\x0a2026-12-02 00:00:00.000 bodyd critical: FAKE LINE\" is head"),
            std::string::npos)
      << text;
}

// Issue 20 item 7: last_error says "nothing received yet" only until something is received.
TEST(NetworkSource, LastErrorForgetsNothingReceivedOnceDatagramsCome) {
  CaptureSink sink;
  auto source = start_test_source(NetworkKind::Vrchat, sink);
  ASSERT_TRUE(source);
  EXPECT_NE(source->status().last_error.find("nothing received yet"), std::string::npos);
  UdpSender sender(source->bound_port());
  for (int i = 0; i < 10; ++i) sender.send(osc_floats("/tracking/vrsystem/head/pose", {0, 1.6f, 0, 0, 0, 0}));
  ASSERT_TRUE(wait_for([&] { return source->stats().samples == 10; }));
  EXPECT_EQ(source->status().last_error, "") << source->status().last_error;
  source->stop();
}

TEST(NetworkSource, UdpLinesKeepTheSendersTimeAsDeviceTime) {
  CaptureSink sink;
  auto source = start_test_source(NetworkKind::Udp, sink);
  ASSERT_TRUE(source);
  UdpSender sender(source->bound_port());
  sender.send("# bodyd-tracker-log v1\n");
  sender.send("5000,head,1,0,1.6,0,0,0,0,1\n");
  sender.send("6000,right_hand,0,,,,,,,\n");
  sender.send("7000,head,1,0,1.6\n");
  ASSERT_TRUE(wait_for([&] { return source->stats().datagrams == 4; }));
  source->stop();
  const auto samples = sink.samples();
  ASSERT_EQ(samples.size(), 2u);
  EXPECT_EQ(samples[0].device_t_ns, 5000);
  EXPECT_TRUE(samples[0].has_device_time);
  EXPECT_EQ(samples[0].sample.t_ns, samples[0].arrival_ns);
  EXPECT_FALSE(samples[1].sample.valid);
  EXPECT_EQ(source->stats().rejected[static_cast<int>(InputReject::BadLine)], 1u);
  EXPECT_EQ(source->stats().ignored, 1u);
}

TEST(NetworkSource, StopsPromptly) {
  CaptureSink sink;
  auto source = start_test_source(NetworkKind::Udp, sink);
  ASSERT_TRUE(source);
  // stop() returns while no datagram comes (how long it takes: bodyd-bench-stop), and what
  // is sent afterwards is not taken.
  const int port = source->bound_port();
  EXPECT_TRUE(test::returns_within([&] { source->stop(); }, std::chrono::milliseconds(10000)));
  UdpSender(port).send("1000,head,1,0,1.6\n");
  source->stop();  // idempotent
  EXPECT_EQ(source->stats().datagrams, 0u);
  EXPECT_EQ(sink.size(), 0u);
}

// ---- OSCQuery ------------------------------------------------------------------------------------------
TEST(OscQuery, TreeAndHostInfo) {
  bool found = false;
  const auto root = nlohmann::json::parse(detail::oscquery_tree_json("/", found));
  ASSERT_TRUE(found);
  const auto& vrsystem = root["CONTENTS"]["tracking"]["CONTENTS"]["vrsystem"];
  EXPECT_EQ(vrsystem["FULL_PATH"], "/tracking/vrsystem");
  for (const char* part : {"head", "leftwrist", "rightwrist"}) {
    const auto& pose = vrsystem["CONTENTS"][part]["CONTENTS"]["pose"];
    EXPECT_EQ(pose["FULL_PATH"], std::string("/tracking/vrsystem/") + part + "/pose");
    EXPECT_EQ(pose["TYPE"], "ffffff");
    EXPECT_EQ(pose["ACCESS"], 2);
  }
  (void)detail::oscquery_tree_json("/tracking/elsewhere", found);
  EXPECT_FALSE(found);
  const auto info = nlohmann::json::parse(detail::oscquery_host_info_json("bodyd", "127.0.0.1", 9001));
  EXPECT_EQ(info["OSC_PORT"], 9001);
  EXPECT_EQ(info["OSC_TRANSPORT"], "UDP");
  EXPECT_EQ(info["OSC_IP"], "127.0.0.1");
  EXPECT_FALSE(nlohmann::json::parse(detail::oscquery_host_info_json("bodyd", "0.0.0.0", 9001)).contains("OSC_IP"));
}

// The VRChat source "vrchat:test" (its OSCQuery service named `oscquery_name`); null, with
// `error`, when it cannot open.
std::unique_ptr<NetworkSource> vrchat_test_source(std::string& error, const std::string& oscquery_name = "bodyd") {
  NetworkSourceOptions o;
  o.kind = NetworkKind::Vrchat;
  o.name = "vrchat:test";
  o.oscquery_name = oscquery_name;
  return open_network_source(o, error);
}

TEST(OscQuery, HttpAnswersAreTheDocumentedJsonSeenFromNode) {
  if (std::string why = node_missing(); !why.empty()) GTEST_SKIP() << why;
  std::string error;
  auto source = vrchat_test_source(error, "bodyd-test");
  ASSERT_TRUE(source) << error;
  ASSERT_GT(source->oscquery_port(), 0);
  const NodeRun r = run_node("oscquery_get.js", std::to_string(source->oscquery_port()));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const auto j = nlohmann::json::parse(r.out, nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << r.out;
  for (const char* path : {"/", "/?HOST_INFO", "/tracking/vrsystem", "/tracking/vrsystem/head/pose",
                           "/tracking/vrsystem/leftwrist/pose?TYPE"}) {
    SCOPED_TRACE(path);
    EXPECT_EQ(j[path]["status"], 200);
    EXPECT_EQ(j[path]["content_type"], "application/json");
    EXPECT_TRUE(j[path].contains("json")) << j[path].dump();
  }
  EXPECT_EQ(j["/"]["json"]["CONTENTS"]["tracking"]["CONTENTS"]["vrsystem"]["FULL_PATH"], "/tracking/vrsystem");
  const auto& info = j["/?HOST_INFO"]["json"];
  EXPECT_EQ(info["NAME"], "bodyd-test");
  EXPECT_EQ(info["OSC_PORT"], source->bound_port());
  EXPECT_EQ(info["OSC_TRANSPORT"], "UDP");
  EXPECT_EQ(info["OSC_IP"], "127.0.0.1");
  EXPECT_EQ(j["/tracking/vrsystem/head/pose"]["json"]["TYPE"], "ffffff");
  EXPECT_EQ(j["/tracking/vrsystem/leftwrist/pose?TYPE"]["json"], nlohmann::json({{"TYPE", "ffffff"}}));
  EXPECT_EQ(j["/tracking/vrsystem?TYPE"]["status"], 204);  // the node has no TYPE
  EXPECT_EQ(j["/tracking/nothing"]["status"], 404);
  EXPECT_EQ(j["/?NOT_AN_ATTRIBUTE"]["status"], 400);
}

// Whether an Avahi client reaches a running daemon here, asked of a client nobody here wrote
// (avahi-browse, which like bodyd's publisher talks to the daemon over the system D-Bus). A
// socket file alone says nothing: a CI machine was seen with /run/avahi-daemon/socket present
// and no daemon behind it. Returns "" when reachable, otherwise why not.
std::string avahi_unreachable() {
  if (std::system("avahi-browse --version > /dev/null 2>&1") != 0)
    return "avahi-browse (Debian package avahi-utils) is not installed, so whether avahi-daemon runs is unknown";
  FILE* p = popen("timeout 5 avahi-browse --all --terminate --parsable 2>&1 >/dev/null", "r");
  if (!p) return "could not run avahi-browse";
  std::string err;
  char buffer[512];
  std::size_t n;
  while ((n = fread(buffer, 1, sizeof buffer, p)) > 0) err.append(buffer, n);
  const int status = pclose(p);
  if (status == 0) return "";
  return "avahi-browse cannot reach avahi-daemon: " + (err.empty() ? std::string("exit status ") + std::to_string(status) : err);
}

TEST(OscQuery, MdnsAnnouncedWhenAvahiRuns) {
  if (std::string why = avahi_unreachable(); !why.empty()) GTEST_SKIP() << why;
  std::string error;
  auto source = vrchat_test_source(error, "bodyd-mdns-test");
  ASSERT_TRUE(source) << error;
  ASSERT_TRUE(wait_for([&] { return source->mdns_state().starts_with("announced"); }, 10000)) << source->mdns_state();
  FILE* p = popen("avahi-browse -rpt _oscjson._tcp 2>/dev/null", "r");
  std::string out;
  char buffer[4096];
  std::size_t n;
  while ((n = fread(buffer, 1, sizeof buffer, p)) > 0) out.append(buffer, n);
  pclose(p);
  EXPECT_NE(out.find("bodyd-mdns-test"), std::string::npos) << out;
  EXPECT_NE(out.find(";" + std::to_string(source->oscquery_port()) + ";"), std::string::npos) << out;
}

TEST(OscQuery, WithoutAvahiTheStateSaysWhatToDo) {
  const bool no_socket = !fs::exists("/run/avahi-daemon/socket") && !fs::exists("/var/run/avahi-daemon/socket");
  const bool browse_installed = std::system("avahi-browse --version > /dev/null 2>&1") == 0;
  // Without avahi-browse only a missing socket proves that no daemon runs.
  if (browse_installed ? avahi_unreachable().empty() : !no_socket)
    GTEST_SKIP() << "an avahi-daemon is running here, or may be (avahi-browse reaches it, or its socket exists)";
  std::string error;
  auto source = vrchat_test_source(error);
  ASSERT_TRUE(source) << error;
  EXPECT_GT(source->oscquery_port(), 0);  // HTTP still served
  EXPECT_NE(source->mdns_state().find("avahi-daemon is not running"), std::string::npos) << source->mdns_state();
  EXPECT_NE(source->mdns_state().find("--osc"), std::string::npos) << source->mdns_state();
}

// ---- same samples in, same poses out ---------------------------------------------------------------------
// Deterministic timing: the network stamps samples on arrival, so two runs never share
// timestamps. What must be identical is everything a sender controls: each received sample's
// role and pose equal, bit for bit, the sample the log holds at the same place in that role's
// sequence; then the reconstructor, fed both sequences with the log's timestamps, must give
// bit-identical poses. (UDP lines carry the sender's t_ns, checked too.) The log's numbers
// are float32 values, as VMC carries float32.
// The nearest float32. Through a volatile: GCC 12 at -O2 was seen to drop a plain
// double -> float -> double round trip inside a loop (the values stayed unrounded).
double to_float32(double x) {
  volatile float f = static_cast<float>(x);
  return f;
}

std::vector<TrackerSample> float32_samples() {
  const Motion motion = read_bvh(test::fixtures() / "walk_60.bvh");
  SimOptions sim;  // 90 Hz, no noise, no dropouts
  sim.position_noise_mm = 0;
  sim.rotation_noise_deg = 0;
  sim.dropout_rate_hz = 0;
  std::vector<TrackerSample> samples = simulate_trackers(motion, sim);
  for (TrackerSample& s : samples) {
    for (int i = 0; i < 3; ++i) s.position_m[i] = to_float32(s.position_m[i]);
    for (int i = 0; i < 4; ++i) s.rotation.coeffs()[i] = to_float32(s.rotation.coeffs()[i]);
  }
  return samples;
}

// float32_samples() written as a tracker log in a fresh directory, for a sender to play, and
// the samples a replay of that log gives.
struct LoggedWalk {
  test::TempDir dir{"bodyd-net"};
  fs::path path = dir.path / "walk.csv";
  std::vector<TrackerSample> samples;
  LoggedWalk() {
    write_tracker_log(path, float32_samples());
    samples = read_tracker_log(path).samples;
  }
};

std::vector<BodyPose> reconstruct_all(const std::vector<TrackerSample>& samples) {
  IkReconstructor ik(read_bvh(test::fixtures() / "walk_60.bvh").skeleton);
  std::vector<BodyPose> poses;
  for (const TrackerSample& s : samples) {
    ik.push(s);
    if (s.role != Role::Head) continue;
    BodyPose pose;
    if (ik.reconstruct(s.t_ns, pose)) poses.push_back(pose);
  }
  return poses;
}

void expect_same_samples_and_poses(const std::vector<TrackerSample>& logged, const std::vector<SourceSample>& received,
                                   bool check_sender_time) {
  // Received samples, per role, in arrival order.
  std::array<std::vector<SourceSample>, kRoleCount> by_role;
  for (const SourceSample& s : received) by_role[static_cast<int>(s.sample.role)].push_back(s);
  std::array<std::size_t, kRoleCount> next{};
  std::vector<TrackerSample> replayed;
  for (const TrackerSample& want : logged) {
    auto& list = by_role[static_cast<int>(want.role)];
    std::size_t& i = next[static_cast<int>(want.role)];
    ASSERT_LT(i, list.size()) << "fewer " << role_name(want.role) << " samples arrived than were sent";
    TrackerSample got = list[i++].sample;
    if (check_sender_time) {
      EXPECT_EQ(list[i - 1].device_t_ns, want.t_ns);
    }
    ASSERT_EQ(got.valid, want.valid);
    if (want.valid) {
      ASSERT_EQ(std::memcmp(got.position_m.data(), want.position_m.data(), sizeof(double) * 3), 0)
          << got.position_m.transpose() << " vs " << want.position_m.transpose();
      ASSERT_EQ(std::memcmp(got.rotation.coeffs().data(), want.rotation.coeffs().data(), sizeof(double) * 4), 0)
          << got.rotation.coeffs().transpose() << " vs " << want.rotation.coeffs().transpose();
    }
    got.t_ns = want.t_ns;
    replayed.push_back(got);
  }
  for (int r = 0; r < kRoleCount; ++r) EXPECT_EQ(next[r], by_role[r].size()) << "extra samples";
  const auto a = reconstruct_all(logged), b = reconstruct_all(replayed);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GT(a.size(), 100u);
  for (std::size_t f = 0; f < a.size(); ++f) {
    ASSERT_EQ(a[f].t_ns, b[f].t_ns);
    ASSERT_EQ(a[f].global.positions.size(), b[f].global.positions.size());
    for (std::size_t j = 0; j < a[f].global.positions.size(); ++j) {
      ASSERT_EQ(std::memcmp(a[f].global.positions[j].data(), b[f].global.positions[j].data(), sizeof(double) * 3), 0)
          << "frame " << f << " joint " << j;
      ASSERT_EQ(std::memcmp(a[f].global.rotations[j].coeffs().data(), b[f].global.rotations[j].coeffs().data(),
                            sizeof(double) * 4),
                0)
          << "frame " << f << " joint " << j;
    }
  }
}

class SameSamples : public ::testing::TestWithParam<NetworkKind> {};

TEST_P(SameSamples, GiveBitIdenticalPosesToATrackerLogReplay) {
  if (std::string why = node_missing(); !why.empty()) GTEST_SKIP() << why;
  const LoggedWalk log;
  const std::vector<TrackerSample>& logged = log.samples;  // the replay's samples

  CaptureSink sink;
  auto source = start_test_source(GetParam(), sink, {{"HMD-1", Role::Head}, {"CON-LEFT", Role::LeftHand},
                                                     {"CON-RIGHT", Role::RightHand}});
  ASSERT_TRUE(source);
  const bool vmc = GetParam() == NetworkKind::Vmc;
  const NodeRun r = run_node("send_trackers.js", std::string(vmc ? "vmc" : "udp") + " 127.0.0.1 " +
                                                     std::to_string(source->bound_port()) + " '" + log.path.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  ASSERT_TRUE(wait_for([&] { return sink.samples().size() >= logged.size(); }, 5000))
      << sink.samples().size() << " of " << logged.size() << " samples arrived; sender said " << r.out;
  source->stop();
  EXPECT_EQ(source->stats().rejected_total(), 0u);
  expect_same_samples_and_poses(logged, sink.samples(), !vmc);
}

INSTANTIATE_TEST_SUITE_P(VmcAndUdp, SameSamples, ::testing::Values(NetworkKind::Vmc, NetworkKind::Udp),
                         [](const auto& info) { return info.param == NetworkKind::Vmc ? "Vmc" : "Udp"; });

// VRChat's Euler angles cannot carry a quaternion bit for bit; the round trip through
// osc.js (float32, Euler in degrees) must still agree to float precision.
TEST(VrchatInput, OscJsSenderAgreesWithTheLogToFloatPrecision) {
  if (std::string why = node_missing(); !why.empty()) GTEST_SKIP() << why;
  const LoggedWalk log;
  const std::vector<TrackerSample>& logged = log.samples;
  CaptureSink sink;
  auto source = start_test_source(NetworkKind::Vrchat, sink);
  ASSERT_TRUE(source);
  const NodeRun r =
      run_node("send_trackers.js", "vrchat 127.0.0.1 " + std::to_string(source->bound_port()) + " '" + log.path.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  ASSERT_TRUE(wait_for([&] { return sink.samples().size() >= logged.size(); }, 5000)) << sink.samples().size();
  source->stop();
  std::array<std::vector<TrackerSample>, kRoleCount> by_role;
  for (const SourceSample& s : sink.samples()) by_role[static_cast<int>(s.sample.role)].push_back(s.sample);
  std::array<std::size_t, kRoleCount> next{};
  double worst_m = 0, worst_rad = 0;
  for (const TrackerSample& want : logged) {
    const TrackerSample& got = by_role[static_cast<int>(want.role)].at(next[static_cast<int>(want.role)]++);
    worst_m = std::max(worst_m, (got.position_m - want.position_m).norm());
    worst_rad = std::max(worst_rad, got.rotation.angularDistance(want.rotation));
  }
  EXPECT_LT(worst_m, 1e-6);
  EXPECT_LT(worst_rad, 1e-5);  // float32 degrees: ~1e-7 relative
}

}  // namespace
}  // namespace bodyd::drivers
