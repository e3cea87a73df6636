// --record-trackers (docs/daemon.md): a live session (simulated trackers, paced at host time)
// recorded and replayed with --replay --fast gives bit-identical poses.
#include "bodyd/motion/tracker_log.h"
#include "bodyd/protocol/pose_message.h"
#include "bodyd/test/files.h"
#include "bodyd/test/net.h"
#include "bodyd/test/process.h"
#include "bodyd/test/pose_message.h"
#include "bodyd/test/temp_dir.h"
#include "../daemon_programs.h"
#include "../test_paths.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <map>
#include <optional>
#include <memory>
#include <sstream>
#include <thread>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;

// The live sessions must reconstruct in real time (one pose per head sample at 90 Hz). A Debug
// build with AddressSanitizer (make sanitize) runs the diffusion model at about 30 ms a frame, so
// there every session of these tests uses the ik method; make test runs them with the default
// diffusion model.
#if defined(__SANITIZE_ADDRESS__)
const std::vector<std::string> kMethodArgs = {"--method", "ik"};
#else
const std::vector<std::string> kMethodArgs = {};
#endif

// Runs bodyd with `args` plus a pose endpoint, --exit-at-end and --wait-for-subscriber, and
// returns every pose it published.
std::vector<protocol::PoseMessage> run_and_collect(std::vector<std::string> args, const fs::path& dir,
                                                   const std::string& name, std::string& log) {
  const fs::path endpoints = dir / (name + ".json");
  const std::string pub = "ipc://" + (dir / (name + ".pose")).string();
  args.insert(args.begin(), kBodyd);
  args.insert(args.end(), kMethodArgs.begin(), kMethodArgs.end());
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
  TempDir dir;
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
    // Every field but the publish time, the floats bit-identical (also telling -0 from 0).
    ASSERT_TRUE(same_pose(live[i], replay[i], /*compare_publish_time=*/false));
  }
}

// The same over the network: a sender streams tracker-log lines over UDP at their recorded pace
// (--source udp:, docs/vr-apps.md), bodyd stamps them on arrival and records them.
TEST(RecordTrackers, LiveUdpSessionReplaysToBitIdenticalPoses) {
  TempDir dir;
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
  std::vector<std::string> live_args{kBodyd, "--source", "udp:127.0.0.1:" + std::to_string(port), "--record-trackers",
                                     recording.string(), "--pub", pub, "--control", control, "--send-hwm", "100000",
                                     "--endpoints-file", (dir.path / "live.json").string()};
  live_args.insert(live_args.end(), kMethodArgs.begin(), kMethodArgs.end());
  Process bodyd(live_args, {.output_dir = dir.path, .name = "live"});
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
  std::uint64_t samples_in = 0;
  for (int i = 0; i < 100 && samples_in < samples.size(); ++i) {
    const std::optional<std::string> reply = status_reply(ctx, control, 3000);
    ASSERT_TRUE(reply);
    samples_in = nlohmann::json::parse(*reply)["samples_in"].get<std::uint64_t>();
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

// Issue 20: a live udp: session recorded by bodyd (`extra` flags, e.g. --overwrite), the
// control socket to ask for samples_in, and a sender of tracker-log lines.
class UdpRecording {
 public:
  UdpRecording(const fs::path& dir, const fs::path& recording, std::vector<std::string> prefix = {},
               std::vector<std::string> extra = {})
      : dir_(dir), control_("ipc://" + (dir / "rec.control").string()) {
    port_ = free_loopback_port();
    std::vector<std::string> args = prefix;
    for (const std::string& a : {kBodyd, std::string("--method"), std::string("ik"), std::string("--source"),
                                 "udp:127.0.0.1:" + std::to_string(port_), std::string("--record-trackers"),
                                 recording.string(), std::string("--pub"), "ipc://" + (dir / "rec.pose").string(),
                                 std::string("--control"), control_, std::string("--endpoints-file"),
                                 (dir / "rec.json").string()})
      args.push_back(a);
    args.insert(args.end(), extra.begin(), extra.end());
    bodyd_ = std::make_unique<Process>(args, ProcessOptions{.output_dir = dir, .name = "rec"});
    started_ = wait_for_file(dir / "rec.json", 20000).has_value();
    samples_ = read_tracker_log(source_dir() / "data/demo/walk.csv").samples;
  }
  bool started() const { return started_; }
  Process& bodyd() { return *bodyd_; }

  // Sends the bundled recording's first `n` samples, one line per datagram, 8 at a time (the
  // head times increase; a burst stays well within the socket's receive buffer).
  void send(std::size_t n) {
    const int fd = socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    to.sin_port = htons(static_cast<std::uint16_t>(port_));
    for (std::size_t i = 0; i < n; ++i) {
      std::string line;
      append_tracker_sample(line, samples_[i]);
      sendto(fd, line.data(), line.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof(to));
      // Within the socket buffer (about 250 small datagrams) even while bodyd's receiver waits
      // for a busy CPU, as in make sanitize's parallel tests (8 a millisecond dropped some there).
      if (i % 2 == 1) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    close(fd);
  }

  // The daemon's samples_in once it reaches `n` (or the last value seen after ~10 s).
  std::uint64_t wait_samples_in(std::uint64_t n) {
    zmq::context_t ctx;
    std::uint64_t in = 0;
    for (int i = 0; i < 200 && in < n; ++i) {
      const std::optional<std::string> reply = status_reply(ctx, control_, 3000);
      if (!reply) break;
      in = nlohmann::json::parse(*reply)["samples_in"].get<std::uint64_t>();
      if (in < n) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return in;
  }

 private:
  fs::path dir_;
  std::string control_;
  int port_ = 0;
  std::unique_ptr<Process> bodyd_;
  bool started_ = false;
  std::vector<TrackerSample> samples_;
};


// Issue 20 item 3: closing the terminal (SIGHUP) stops bodyd as SIGTERM does, with the
// recording written and the "stopped" line logged.
TEST(RecordTrackers, SighupStopsCleanlyWithTheRecordingWritten) {
  TempDir dir;
  const fs::path recording = dir.path / "r.csv";
  UdpRecording session(dir.path, recording);
  ASSERT_TRUE(session.started()) << session.bodyd().log();
  session.send(300);
  ASSERT_EQ(session.wait_samples_in(300), 300u) << session.bodyd().log();
  session.bodyd().signal(SIGHUP);
  ASSERT_EQ(session.bodyd().wait(20000), 0) << session.bodyd().log();  // 129 (killed by SIGHUP) before
  const std::string err = session.bodyd().err();
  EXPECT_NE(err.find("signal received (Hangup): shutting down"), std::string::npos) << err;
  EXPECT_NE(err.find("stopped:"), std::string::npos) << err;
  EXPECT_NE(err.find("300 samples recorded"), std::string::npos) << err;
  EXPECT_EQ(read_tracker_log(recording).samples.size(), 300u);
}

// Issue 20 item 3: the recording reaches the file within about half a second, so a kill -9
// loses at most that; what is on disk reads back as a tracker log.
TEST(RecordTrackers, AKillLosesAtMostTheLastSecond) {
  TempDir dir;
  const fs::path recording = dir.path / "r.csv";
  UdpRecording session(dir.path, recording);
  ASSERT_TRUE(session.started()) << session.bodyd().log();
  session.send(300);  // about 20 KB of lines: less than the 64 KiB buffer
  ASSERT_EQ(session.wait_samples_in(300), 300u) << session.bodyd().log();
  // Nothing more arrives; the periodic write must bring every sample to the file (before the
  // fix it stayed in the buffer until 64 KiB or exit).
  for (int i = 0; i < 100 && samples_on_disk(recording) < 300; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  session.bodyd().signal(SIGKILL);
  session.bodyd().wait(10000);
  EXPECT_EQ(samples_on_disk(recording), 300u);
  EXPECT_EQ(read_tracker_log(recording).samples.size(), 300u);
}

// Issue 20 item 5: after a write error (here the file-size limit, RLIMIT_FSIZE, which bodyd
// turns into an error instead of dying of SIGXFSZ) the log says what the file really holds,
// and the file is cut back to whole lines.
TEST(RecordTrackers, AWriteErrorReportsWhatWasReallyWritten) {
  if (!fs::exists("/usr/bin/prlimit")) GTEST_SKIP() << "prlimit (util-linux) is not installed";
  TempDir dir;
  const fs::path recording = dir.path / "r.csv";
  // 24 KiB for every file bodyd writes: the recording, and its own log (which stays smaller).
  UdpRecording session(dir.path, recording, {"/usr/bin/prlimit", "--fsize=24576", "--"});
  ASSERT_TRUE(session.started()) << session.bodyd().log();
  session.send(1000);  // about 70 KB of lines
  ASSERT_EQ(session.wait_samples_in(1000), 1000u) << session.bodyd().log();
  session.bodyd().signal(SIGTERM);
  ASSERT_EQ(session.bodyd().wait(20000), 0) << session.bodyd().log();
  const std::string err = session.bodyd().err();
  const std::size_t in_file = read_tracker_log(recording).samples.size();  // whole lines only
  EXPECT_GT(in_file, 0u);
  EXPECT_LT(in_file, 1000u);
  EXPECT_NE(err.find("write failed after " + std::to_string(in_file) + " samples"), std::string::npos) << err;
  EXPECT_NE(err.find("incomplete: " + std::to_string(in_file) + " samples recorded, " + std::to_string(1000 - in_file) +
                     " not recorded"),
            std::string::npos)
      << err;
  EXPECT_EQ(err.find("1000 samples recorded"), std::string::npos) << err;
}

// Issue 20 item 5: an existing file, a symbolic link (even with --overwrite) and a FIFO are
// refused before anything else starts; --overwrite (or config "overwrite") replaces a file.
TEST(RecordTrackers, ExistingFilesLinksAndFifosAreRefused) {
  TempDir dir;
  const std::vector<std::string> base{kBodyd, "--method", "ik", "--pub", "ipc://" + (dir.path / "pose").string(),
                                      "--control", "none", "--record-trackers"};
  auto bodyd_recording = [&](const fs::path& file, std::vector<std::string> extra = {}) {
    auto args = base;
    args.push_back(file.string());
    args.insert(args.end(), extra.begin(), extra.end());
    return run(args, {.output_dir = dir.path}, 20000);  // -1: it hung (a FIFO opened blocking)
  };
  std::ofstream(dir.path / "t") << "precious\n";
  fs::create_symlink(dir.path / "t", dir.path / "l.csv");
  RunResult r = bodyd_recording(dir.path / "t");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("exists"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--overwrite"), std::string::npos) << r.err;
  for (const auto& extra : {std::vector<std::string>{}, std::vector<std::string>{"--overwrite"}}) {
    r = bodyd_recording(dir.path / "l.csv", extra);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("symbolic link"), std::string::npos) << r.err;
  }
  EXPECT_EQ(read_file(dir.path / "t"), "precious\n");
  ASSERT_EQ(mkfifo((dir.path / "f.csv").c_str(), 0600), 0);
  r = bodyd_recording(dir.path / "f.csv");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("not a regular file"), std::string::npos) << r.err;

  // --overwrite, and the config key, replace a regular file.
  const std::string log = (dir.path / "log.csv").string();
  std::vector<TrackerSample> first = read_tracker_log(source_dir() / "data/demo/walk.csv").samples;
  first.resize(30);
  write_tracker_log(log, first);
  r = bodyd_recording(dir.path / "t", {"--overwrite", "--replay", log, "--fast", "--exit-at-end"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_tracker_log(dir.path / "t").samples.size(), 30u);
  std::ofstream(dir.path / "config.json") << R"({"overwrite": true})";
  r = bodyd_recording(dir.path / "t", {"--config", (dir.path / "config.json").string(), "--replay", log, "--fast",
                                       "--exit-at-end"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_tracker_log(dir.path / "t").samples.size(), 30u);
}

// Issue 20 item 3: USR1, USR2 and ALRM are ignored (bodyd keeps running and answering); QUIT
// stops it cleanly like TERM.
TEST(Signals, UsrAndAlrmAreIgnoredQuitStopsCleanly) {
  TempDir dir;
  const std::string control = ipc_control(dir.path);
  Process bodyd = idle_bodyd(dir.path);
  ASSERT_TRUE(wait_for_file(dir.path / "endpoints.json", 20000)) << bodyd.log();
  for (int sig : {SIGUSR1, SIGUSR2, SIGALRM}) bodyd.signal(sig);
  zmq::context_t ctx;
  ASSERT_TRUE(status_reply(ctx, control)) << bodyd.log();  // still there
  EXPECT_FALSE(bodyd.wait(0)) << bodyd.log();
  bodyd.signal(SIGQUIT);
  ASSERT_EQ(bodyd.wait(20000), 0) << bodyd.log();  // 131 (core dump) before
  EXPECT_NE(bodyd.err().find("stopped:"), std::string::npos) << bodyd.err();
}

TEST(RecordTrackers, UnwritableFileIsAStartError) {
  TempDir dir;
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
