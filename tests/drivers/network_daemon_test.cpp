// End to end: bodyd with the network inputs (vrchat:, vmc:, udp:). Good VRChat poses at
// 90 Hz keep the daemon publishing while every malformed kind of packet is sent to each
// input; the daemon must keep publishing finite poses, count each bad packet under its
// reason in `status`, and say so in its log (rate-limited).
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/tracker_log.h"
#include "bodyd/protocol/pose_message.h"
#include "bodyd/simulators/tracker_sim.h"

#include "../daemon_programs.h"
#include "../test_paths.h"
#include "pose_sub_helpers.h"
#include "osc_helpers.h"

#include "bodyd/test/files.h"
#include "bodyd/test/net.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"
#include "bodyd/test/wait.h"

#include <gtest/gtest.h>
#include <lo/lo.h>
#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <thread>

namespace bodyd {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

using test::read_file;

// bodyd's arguments for an IK daemon on loopback TCP (pub on any port, control on a free one)
// with its endpoints file dir/endpoints.json, reading `sources`.
std::vector<std::string> ik_daemon_args(const fs::path& dir, const std::vector<std::string>& sources) {
  std::vector<std::string> args = {"--method", "ik", "--pub", "tcp://127.0.0.1:*", "--control",
                                   "tcp://127.0.0.1:" + std::to_string(test::free_loopback_port(SOCK_STREAM)),
                                   "--endpoints-file", (dir / "endpoints.json").string()};
  for (const std::string& source : sources) args.insert(args.end(), {"--source", source});
  return args;
}

// The daemon's --endpoints-file (dir/endpoints.json) once it names the control endpoint
// (waiting up to 10 s); an empty object if it never does.
nlohmann::json wait_for_endpoints(const fs::path& dir) {
  nlohmann::json endpoints = nlohmann::json::object();
  test::eventually(
      [&] {
        endpoints = nlohmann::json::parse(read_file(dir / "endpoints.json"), nullptr, false);
        if (endpoints.is_discarded()) endpoints = nlohmann::json::object();
        return endpoints.contains("control");
      },
      std::chrono::milliseconds(10000));
  return endpoints;
}

// A SUB socket taking everything from `pub`, connected long enough for the subscription to
// reach the publisher.
zmq::socket_t subscribe_all(zmq::context_t& ctx, const std::string& pub) {
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::subscribe, "");
  sub.connect(pub);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  return sub;
}

// bodyd as a child process (ik_daemon_args, reading `sources`), stdout and stderr in files in
// `dir`; once it is up, its endpoints (wait_for_endpoints) and a SUB socket taking all it
// publishes (subscribe_all).
class Daemon : public test::Process {
 public:
  Daemon(const fs::path& dir, const std::vector<std::string>& sources)
      : Process(with_bodyd(ik_daemon_args(dir, sources)), {.stdout_path = dir / "stdout", .stderr_path = dir / "stderr"}),
        endpoints(wait_for_endpoints(dir)) {
    if (up()) sub = subscribe_all(ctx, endpoints["pub"].get<std::string>());
  }
  // Its endpoints name the control socket (and `sub` is connected).
  bool up() const { return endpoints.contains("control"); }
  // SIGTERM; the exit code within timeout_ms, or nullopt.
  std::optional<int> stop(int timeout_ms) { return terminate(timeout_ms); }

  nlohmann::json endpoints;
  zmq::context_t ctx;
  zmq::socket_t sub;

 private:
  static std::vector<std::string> with_bodyd(std::vector<std::string> args) {
    args.insert(args.begin(), BODYD_EXE);
    return args;
  }
};

// Why a test that plays trackers with osc.js cannot run (node or the npm package osc is
// missing); empty when it can.
std::string osc_js_skip_reason() {
  if (std::system("node --version > /dev/null 2>&1") != 0) return "node is not installed (scripts/setup)";
  if (!fs::exists(test::source_dir() / "tests/node/node_modules/osc/package.json"))
    return "the npm package osc is not installed in tests/node (scripts/setup runs npm ci there)";
  return "";
}

// Plays dir/walk.csv to 127.0.0.1:port as `kind` (vrchat, vmc) sends it, one time step each
// 11 ms (tests/drivers/node/send_trackers.js); its output goes to dir/sender.txt.
void play_tracker_log(const std::string& kind, int port, const fs::path& dir) {
  const std::string command = "NODE_PATH='" + (test::source_dir() / "tests/node/node_modules").string() + "' node '" +
                              (test::source_dir() / "tests/drivers/node/send_trackers.js").string() + "' " + kind +
                              " 127.0.0.1 " + std::to_string(port) + " '" + (dir / "walk.csv").string() + "' 11 > '" +
                              (dir / "sender.txt").string() + "' 2>&1";
  EXPECT_EQ(std::system(command.c_str()), 0) << test::read_file(dir / "sender.txt");
}

// Calls on_pose with every pose that arrives on `sub` for `duration`; returns how many came.
template <class OnPose>
int collect_poses(zmq::socket_t& sub, std::chrono::seconds duration, OnPose&& on_pose) {
  int poses = 0;
  const auto end = std::chrono::steady_clock::now() + duration;
  while (std::chrono::steady_clock::now() < end) {
    const std::optional<protocol::PoseMessage> next = test::poll_pose(sub, std::chrono::milliseconds(50));
    if (!next) continue;
    ++poses;
    on_pose(*next);
  }
  return poses;
}

// The daemon's status (a {"cmd":"status"} request on its control endpoint), with its sources.
nlohmann::json daemon_status(Daemon& daemon) {
  const std::optional<std::string> reply = test::status_reply(daemon.ctx, daemon.endpoints["control"].get<std::string>());
  EXPECT_TRUE(reply) << daemon.err();
  if (!reply) return {};
  const auto status = nlohmann::json::parse(*reply, nullptr, false);
  EXPECT_TRUE(status.contains("sources")) << *reply;
  return status;
}

using test::osc_floats;
using test::osc_serialise;
using test::osc_vmc;

using test::wrap_in_bundle;

struct Bad {
  int port_index;  // 0 vrchat, 1 vmc, 2 udp
  Bytes bytes;
  const char* reason;
};

std::vector<Bad> bad_packets() {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const Bytes good = osc_floats("/tracking/vrsystem/head/pose", {0, 1.6f, 0, 0, 0, 0});
  std::vector<Bad> b;
  b.push_back({0, Bytes(good.begin(), good.end() - 5), "truncated"});
  b.push_back({0, Bytes{'G', 'E', 'T', ' ', '/', 0, 0, 0}, "not_osc"});
  {
    lo_message m = lo_message_new();
    for (int i = 0; i < 6; ++i) lo_message_add_int32(m, 1);
    b.push_back({0, osc_serialise(m, "/tracking/vrsystem/head/pose"), "bad_type_tags"});
  }
  b.push_back({0, osc_floats("/tracking/vrsystem/head/pose", {0, 1.6f, 0}), "wrong_arg_count"});
  b.push_back({0, osc_floats("/tracking/vrsystem/head/pose", {nan, 1.6f, 0, 0, 0, 0}), "non_finite"});
  b.push_back({0, osc_floats("/tracking/vrsystem/head/pose", {0, 3e8f, 0, 0, 0, 0}), "absurd_value"});
  b.push_back({0, wrap_in_bundle(std::vector<Bytes>(600, good)), "oversized"});
  b.push_back({1, osc_vmc("/VMC/Ext/Hmd/Pos", "H", {0, 1.6f, 0, 0, 0, 0, 5}), "absurd_value"});
  b.push_back({1, osc_vmc("/VMC/Ext/Con/Pos", "C", {0, 1, 0, nan, 0, 0, 1}), "non_finite"});
  b.push_back({1, osc_floats("/VMC/Ext/Con/Pos", {0, 1, 0, 0, 0, 0, 1}), "wrong_arg_count"});
  const std::string lines[] = {"1,head,1,0,1.6,0,0,0,0", "not a tracker-log line"};
  for (const std::string& l : lines) b.push_back({2, Bytes(l.begin(), l.end()), "bad_line"});
  return b;
}

TEST(DaemonNetworkInputs, BadPacketsAreCountedWhilePosesKeepComing) {
  const test::TempDir tmp("bodyd-net-e2e");
  const fs::path& dir = tmp.path;
  const int ports[3] = {test::free_loopback_port(), test::free_loopback_port(), test::free_loopback_port()};
  Daemon daemon(dir, {"vrchat:127.0.0.1:" + std::to_string(ports[0]) + "?oscquery=off",
                      "vmc:127.0.0.1:" + std::to_string(ports[1]), "udp:127.0.0.1:" + std::to_string(ports[2])});
  ASSERT_TRUE(daemon.up()) << daemon.err();

  // The sender: good VRChat poses at 90 Hz for 2 s; the bad packets in the middle second.
  const std::vector<Bad> bad = bad_packets();
  std::atomic<bool> bad_sent{false};
  std::thread sender([&] {
    const int fd = socket(AF_INET, SOCK_DGRAM, 0);
    auto send_to = [&](int port, const Bytes& b) {
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_port = htons(static_cast<std::uint16_t>(port));
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      sendto(fd, b.data(), b.size(), 0, reinterpret_cast<sockaddr*>(&a), sizeof a);
    };
    std::size_t next_bad = 0;
    for (int frame = 0; frame < 180; ++frame) {
      const float t = static_cast<float>(frame) / 90.0f;
      const float sway = 0.05f * std::sin(t * 3.0f);
      send_to(ports[0], wrap_in_bundle({osc_floats("/tracking/vrsystem/head/pose", {sway, 1.6f, 0, 0, 0, 0}),
                                        osc_floats("/tracking/vrsystem/leftwrist/pose", {-0.35f + sway, 1.0f, 0.1f, 0, 0, 0}),
                                        osc_floats("/tracking/vrsystem/rightwrist/pose", {0.35f + sway, 1.0f, 0.1f, 0, 0, 0})}));
      if (frame >= 45 && next_bad < bad.size() && frame % 4 == 0) {
        send_to(ports[bad[next_bad].port_index], bad[next_bad].bytes);
        if (++next_bad == bad.size()) bad_sent.store(true);
      }
      std::this_thread::sleep_for(std::chrono::microseconds(11111));
    }
    close(fd);
  });

  int poses_after_bad = 0, non_finite = 0;
  const int poses = collect_poses(daemon.sub, std::chrono::seconds(4), [&](const protocol::PoseMessage& pose) {
    if (bad_sent.load()) ++poses_after_bad;
    for (const auto& j : pose.joints)
      for (float v : j.position_m) non_finite += !std::isfinite(v);
  });
  sender.join();
  EXPECT_GT(poses, 60) << daemon.err();
  EXPECT_GT(poses_after_bad, 10) << "the daemon stopped publishing after the bad packets\n" << daemon.err();
  EXPECT_EQ(non_finite, 0);

  const nlohmann::json status = daemon_status(daemon);
  ASSERT_TRUE(status.contains("sources"));
  ASSERT_EQ(status["sources"].size(), 3u) << status.dump(2);
  std::map<std::string, int> expected[3];
  for (const Bad& b : bad) ++expected[b.port_index][b.reason];
  for (int i = 0; i < 3; ++i) {
    const auto& s = status["sources"][i];
    SCOPED_TRACE(s.dump());
    EXPECT_EQ(s["rejected"], [&] {
      int n = 0;
      for (const auto& [k, v] : expected[i]) n += v;
      return n;
    }());
    for (const auto& [reason, count] : s["rejected_by_reason"].items())
      EXPECT_EQ(count.get<int>(), expected[i].count(reason) ? expected[i][reason] : 0) << reason;
  }
  EXPECT_EQ(status["sources"][0]["samples"].get<int>(), 3 * 180);
  EXPECT_EQ(daemon.stop(5000), 0) << daemon.err();
  const std::string log = daemon.err();
  EXPECT_NE(log.find("rejected a packet from 127.0.0.1"), std::string::npos) << log;
}

// The VRChat input driving the pose stream: osc.js plays a BVH clip's head and wrists as
// VRChat sends them (/tracking/vrsystem/*/pose, Unity axes and Euler angles, 90 Hz) into
// bodyd --source vrchat:, and a ZeroMQ subscriber receives poses with all three trackers valid.
// (The full VRChat loop, with --output vrchat:, is tested with the outputs: docs/outputs.md.)
TEST(DaemonNetworkInputs, VrchatSenderDrivesThePoseStream) {
  if (const std::string why = osc_js_skip_reason(); !why.empty()) GTEST_SKIP() << why;
  const test::TempDir tmp("bodyd-net-vrc");
  const fs::path& dir = tmp.path;
  SimOptions sim;  // 90 Hz, the clip's motion without noise
  sim.position_noise_mm = 0;
  sim.rotation_noise_deg = 0;
  sim.dropout_rate_hz = 0;
  const std::vector<TrackerSample> samples = simulate_trackers(read_bvh(test::fixtures() / "walk_60.bvh"), sim);
  write_tracker_log(dir / "walk.csv", samples);
  const int port = test::free_loopback_port();
  Daemon daemon(dir, {"vrchat:127.0.0.1:" + std::to_string(port)});
  ASSERT_TRUE(daemon.up()) << daemon.err();

  std::thread sender([&] { play_tracker_log("vrchat", port, dir); });
  const std::uint32_t all = protocol::kFlagHeadValid | protocol::kFlagLeftHandValid | protocol::kFlagRightHandValid;
  int tracked = 0;
  const int poses = collect_poses(daemon.sub, std::chrono::seconds(5), [&](const protocol::PoseMessage& pose) {
    if ((pose.flags & all) == all) ++tracked;
  });
  sender.join();
  const int frames = static_cast<int>(samples.size() / 3);
  EXPECT_GE(tracked, frames * 8 / 10) << poses << " poses, " << tracked << " with all trackers, of " << frames
                                      << " frames sent\n"
                                      << daemon.err();
  EXPECT_EQ(daemon.stop(5000), 0) << daemon.err();
  EXPECT_NE(daemon.err().find("OSCQuery on http://127.0.0.1:"), std::string::npos) << daemon.err();
}

// Issue 20 item 2: one forged VMC packet (a serial holding terminal escapes and a fake log
// line) arrives before the real headset. It may hold the head only until it has been silent
// for a second; then the real headset (osc.js playing the bundled recording) gets it and keeps
// it while a second forged serial sends; the forged serials reach the log escaped.
TEST(DaemonNetworkInputs, AForgedVmcSerialCannotKeepOrStealTheHead) {
  if (const std::string why = osc_js_skip_reason(); !why.empty()) GTEST_SKIP() << why;
  const test::TempDir tmp("bodyd-net-vmc");
  const fs::path& dir = tmp.path;
  std::vector<TrackerSample> samples = read_tracker_log(test::source_dir() / "data/demo/walk.csv").samples;
  samples.resize(3 * 360);  // 360 time steps, 4 s at the sender's 11 ms
  write_tracker_log(dir / "walk.csv", samples);
  const int port = test::free_loopback_port();
  Daemon daemon(dir, {"vmc:127.0.0.1:" + std::to_string(port)});
  ASSERT_TRUE(daemon.up()) << daemon.err();

  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<std::uint16_t>(port));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  auto send = [&](const Bytes& b) { sendto(fd, b.data(), b.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to); };
  const char* forged = "X\x1b[2J\n2026-12-02 00:00:00.000 bodyd critical: FAKE LINE";
  send(osc_vmc("/VMC/Ext/Hmd/Pos", forged, {5, 3, 5, 0, 0, 0, 1}));
  std::this_thread::sleep_for(std::chrono::milliseconds(50));

  std::thread sender([&] { play_tracker_log("vmc", port, dir); });
  // While the real headset streams (from about 2.5 s on): a second forged serial at 30 Hz.
  std::thread forger([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(2500));
    for (int i = 0; i < 15; ++i) {
      send(osc_vmc("/VMC/Ext/Hmd/Pos", "FORGED-2", {5, 3, 5, 0, 0, 0, 1}));
      std::this_thread::sleep_for(std::chrono::milliseconds(33));
    }
  });
  const std::uint32_t all = protocol::kFlagHeadValid | protocol::kFlagLeftHandValid | protocol::kFlagRightHandValid;
  int tracked = 0;
  const int poses = collect_poses(daemon.sub, std::chrono::seconds(5), [&](const protocol::PoseMessage& pose) {
    if ((pose.flags & all) == all) ++tracked;
  });
  sender.join();
  forger.join();
  close(fd);
  // The first second goes to the forged serial's timeout, then HMD-1's poses are tracked (about
  // 100 to 250 in the collection window on a loaded machine; before the fix: the forged serial
  // kept the head and no pose came after the first).
  EXPECT_GE(tracked, 60) << poses << " poses\n" << daemon.err();

  const nlohmann::json status = daemon_status(daemon);
  ASSERT_TRUE(status.contains("sources"));
  // FORGED-2's 15 poses were dropped, never used as the head.
  EXPECT_GE(status["sources"][0]["counters"]["unassigned"].get<int>(), 15) << status.dump(2);
  EXPECT_EQ(daemon.stop(5000), 0) << daemon.err();
  const std::string log = daemon.err();
  EXPECT_NE(log.find("serial \"HMD-1\" is head (the next HMD after \"X\\x1b[2J\\x0a2026-12-02"), std::string::npos)
      << log;
  EXPECT_NE(log.find("serial \"FORGED-2\" ignored: the head is held by \"HMD-1\""), std::string::npos) << log;
  EXPECT_EQ(log.find('\x1b'), std::string::npos) << "a raw escape reached the log";
  EXPECT_EQ(log.find("\n2026-12-02 00:00:00.000 bodyd critical: FAKE"), std::string::npos) << "a forged log line";
}

}  // namespace
}  // namespace bodyd
