// --record-trackers (docs/daemon.md): a live session (simulated trackers, paced at host time)
// recorded and replayed with --replay --fast gives bit-identical poses.
#include "bodyd/motion/tracker_log.h"
#include "bodyd/protocol/pose_message.h"
#include "../install/process.h"
#include "operate_helpers.h"
#include "../test_paths.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <cstring>
#include <map>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;

// Runs bodyd with `args` plus a pose endpoint, --exit-at-end and --wait-for-subscriber, and
// returns every pose it published.
std::vector<protocol::PoseMessage> run_and_collect(std::vector<std::string> args, const fs::path& dir,
                                                   const std::string& name, std::string& log) {
  const fs::path endpoints = dir / (name + ".json");
  const std::string pub = "ipc://" + (dir / (name + ".pose")).string();
  args.insert(args.begin(), kBodyd);
  for (const std::string& a : {std::string("--pub"), pub, std::string("--control"), std::string("none"),
                               std::string("--exit-at-end"), std::string("--wait-for-subscriber"),
                               std::string("--send-hwm"), std::string("100000"), std::string("--endpoints-file"),
                               endpoints.string()})
    args.push_back(a);
  Process bodyd(args, {.output_dir = dir, .name = name});
  std::vector<protocol::PoseMessage> poses;
  if (!wait_for_file(endpoints, 20000)) {
    log = bodyd.log();
    return poses;
  }
  zmq::context_t ctx;
  zmq::socket_t sub = pose_subscriber(ctx, pub);
  for (;;) {
    zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
    if (zmq::poll(&item, 1, std::chrono::milliseconds(poses.empty() ? 10000 : 2000)) <= 0) break;
    zmq::message_t topic, body;
    if (!sub.recv(topic) || !topic.more() || !sub.recv(body)) break;
    protocol::PoseMessage pose;
    const auto* bytes = static_cast<const std::uint8_t*>(body.data());
    if (!protocol::decode_pose(std::vector<std::uint8_t>(bytes, bytes + body.size()), pose).ok()) break;
    poses.push_back(pose);
  }
  const auto code = bodyd.wait(20000);
  log = bodyd.log();
  if (code != 0) poses.clear();
  return poses;
}

TEST(RecordTrackers, LiveSessionReplaysToBitIdenticalPoses) {
  ScratchDir dir;
  const fs::path recording = dir.path / "session.csv";
  std::string live_log, replay_log;
  // A live-like session: simulated trackers from a BVH clip, paced, stamped with host time,
  // with noise and jitter; the default (diffusion) model.
  const auto live = run_and_collect({"--sim", (fixtures() / "walk_60.bvh").string(), "--record-trackers",
                                     recording.string()},
                                    dir.path, "live", live_log);
  ASSERT_GT(live.size(), 100u) << live_log;

  const TrackerLog log = read_tracker_log(recording);
  std::map<std::string, std::string> meta(log.metadata.begin(), log.metadata.end());
  EXPECT_EQ(meta["generator"], "bodyd");
  EXPECT_NE(meta["sources"].find("sim:"), std::string::npos);
  EXPECT_FALSE(meta["calibration"].empty());
  std::size_t heads = 0;
  for (const auto& s : log.samples) heads += s.role == Role::Head;
  EXPECT_EQ(heads, live.size());

  const auto replay = run_and_collect({"--replay", recording.string(), "--fast"}, dir.path, "replay", replay_log);
  ASSERT_EQ(replay.size(), live.size()) << replay_log;
  for (std::size_t i = 0; i < live.size(); ++i) {
    SCOPED_TRACE("pose " + std::to_string(i));
    const auto& a = live[i];
    const auto& b = replay[i];
    ASSERT_EQ(a.seq, b.seq);
    ASSERT_EQ(a.t_ns, b.t_ns);
    ASSERT_EQ(a.flags, b.flags);
    ASSERT_EQ(a.skeleton_id, b.skeleton_id);
    ASSERT_EQ(a.foot_contact, b.foot_contact);
    ASSERT_EQ(a.root_joint, b.root_joint);
    ASSERT_EQ(a.joints.size(), b.joints.size());
    // Bit-identical floats (memcmp: also tells -0 from 0).
    ASSERT_EQ(std::memcmp(a.joints.data(), b.joints.data(), a.joints.size() * sizeof(a.joints[0])), 0);
    ASSERT_EQ(std::memcmp(a.root_position_m.data(), b.root_position_m.data(), sizeof(a.root_position_m)), 0);
  }
}

// The same over the network: a sender streams tracker-log lines over UDP at their recorded pace
// (--source udp:, docs/vr-apps.md), bodyd stamps them on arrival and records them.
TEST(RecordTrackers, LiveUdpSessionReplaysToBitIdenticalPoses) {
  ScratchDir dir;
  const fs::path recording = dir.path / "udp-session.csv";
  // A free UDP port (released just before bodyd binds it).
  int port = 0;
  {
    const int fd = socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof(a);
    ASSERT_EQ(bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0);
    ASSERT_EQ(getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len), 0);
    port = ntohs(a.sin_port);
    close(fd);
  }
  const std::string pub = "ipc://" + (dir.path / "live.pose").string();
  const std::string control = "ipc://" + (dir.path / "live.control").string();
  Process bodyd({kBodyd, "--source", "udp:127.0.0.1:" + std::to_string(port), "--record-trackers", recording.string(),
                 "--pub", pub, "--control", control, "--send-hwm", "100000", "--endpoints-file",
                 (dir.path / "live.json").string()},
                {.output_dir = dir.path, .name = "live"});
  ASSERT_TRUE(wait_for_file(dir.path / "live.json", 20000)) << bodyd.log();
  zmq::context_t ctx;
  zmq::socket_t sub = pose_subscriber(ctx, pub);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the subscription reaches bodyd

  // 2 s of the bundled recording, paced.
  std::vector<TrackerSample> samples = read_tracker_log(source_dir() / "data/demo/walk.csv").samples;
  samples.resize(540);
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  to.sin_port = htons(static_cast<std::uint16_t>(port));
  const auto start = std::chrono::steady_clock::now();
  for (const auto& sample : samples) {
    std::this_thread::sleep_until(start + std::chrono::nanoseconds(sample.t_ns - samples.front().t_ns));
    std::string line;
    append_tracker_sample(line, sample);
    ASSERT_GT(sendto(fd, line.data(), line.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof(to)), 0);
  }
  close(fd);
  // Every sample in (UDP on loopback loses nothing here), then stop bodyd.
  zmq::socket_t req(ctx, zmq::socket_type::req);
  req.set(zmq::sockopt::linger, 0);
  req.set(zmq::sockopt::rcvtimeo, 3000);
  req.connect(control);
  std::uint64_t samples_in = 0;
  for (int i = 0; i < 100 && samples_in < samples.size(); ++i) {
    req.send(zmq::buffer(std::string(R"({"cmd":"status"})")));
    zmq::message_t reply;
    ASSERT_TRUE(req.recv(reply));
    samples_in = nlohmann::json::parse(reply.to_string())["samples_in"].get<std::uint64_t>();
    if (samples_in < samples.size()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(samples_in, samples.size()) << bodyd.log();
  bodyd.signal(SIGTERM);
  ASSERT_EQ(bodyd.wait(20000), 0) << bodyd.log();
  std::vector<protocol::PoseMessage> live;
  for (;;) {
    zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
    if (zmq::poll(&item, 1, std::chrono::milliseconds(500)) <= 0) break;
    zmq::message_t topic, body;
    if (!sub.recv(topic) || !sub.recv(body)) break;
    protocol::PoseMessage pose;
    const auto* bytes = static_cast<const std::uint8_t*>(body.data());
    ASSERT_TRUE(protocol::decode_pose(std::vector<std::uint8_t>(bytes, bytes + body.size()), pose).ok());
    live.push_back(pose);
  }
  ASSERT_EQ(live.size(), 180u) << bodyd.log();  // one per head sample
  EXPECT_EQ(live.front().seq, 0u);

  std::string replay_log;
  const auto replay = run_and_collect({"--replay", recording.string(), "--fast"}, dir.path, "replay", replay_log);
  ASSERT_EQ(replay.size(), live.size()) << replay_log;
  for (std::size_t i = 0; i < live.size(); ++i) {
    SCOPED_TRACE("pose " + std::to_string(i));
    ASSERT_EQ(live[i].t_ns, replay[i].t_ns);
    ASSERT_EQ(live[i].flags, replay[i].flags);
    ASSERT_EQ(std::memcmp(live[i].joints.data(), replay[i].joints.data(), live[i].joints.size() * sizeof(live[i].joints[0])), 0);
  }
}

TEST(RecordTrackers, UnwritableFileIsAStartError) {
  ScratchDir dir;
  const RunResult r = run({kBodyd, "--method", "ik", "--pub", "ipc://" + (dir.path / "pose").string(), "--control",
                           "none", "--record-trackers", (dir.path / "no/such/dir/rec.csv").string()},
                          {.output_dir = dir.path}, 20000);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--record-trackers " + (dir.path / "no/such/dir/rec.csv").string() + ": cannot create"),
            std::string::npos)
      << r.err;
}

}  // namespace
}  // namespace bodyd::test
