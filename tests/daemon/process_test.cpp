// bodyd as a process: end to end over tcp:// and ipc://, equal to an in-process
// reconstruction; clean shutdown on signals and on request; a subscriber surviving a restart;
// clear errors for refused endpoints and bad models.
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/reconstructors.h"
#include "bodyd/motion/tracker_log.h"
#include "../test_paths.h"
#include "pose_compare.h"
#include "zmq_helpers.h"

#include <gtest/gtest.h>

namespace bodyd {
namespace {

const std::string kBodyd = (test::bin_dir() / "bodyd").string();

std::vector<std::string> bodyd_args(std::initializer_list<std::string> extra) {
  // Without auto calibration: the references are at the model's size.
  std::vector<std::string> args{kBodyd, "--method", "ik", "--log-level", "debug", "--no-auto-calibrate"};
  args.insert(args.end(), extra);
  return args;
}

// The bundled recording's first `samples` samples as a log in `dir`.
std::vector<TrackerSample> short_log(const std::filesystem::path& path, std::size_t samples) {
  auto all = read_tracker_log(daemon::bundled_recording_path()).samples;
  all.resize(std::min(all.size(), samples));
  write_tracker_log(path, all);
  return all;
}

void replay_end_to_end(const std::string& pub, bool paced) {
  test::TempDir dir;
  const auto samples = short_log(dir.path / "log.csv", paced ? 450 : 2196);  // paced: 1.7 s
  const auto endpoints_file = dir.path / "endpoints.json";
  std::vector<std::string> args = bodyd_args({"--replay", (dir.path / "log.csv").string(), "--pub", pub, "--control",
                                              "none", "--exit-at-end", "--wait-for-subscriber", "--send-hwm",
                                              "100000", "--endpoints-file", endpoints_file.string()});
  if (!paced) args.push_back("--fast");
  test::Child child(args, dir.path / "stderr.txt");
  const auto endpoints = test::wait_endpoints(endpoints_file, 10000);
  ASSERT_TRUE(endpoints) << child.log();
  const std::string bound = (*endpoints)["pub"];
  if (pub.rfind("tcp://", 0) == 0) {
    EXPECT_NE(bound, pub);  // the port was chosen
  }
  zmq::context_t ctx;
  auto sub = test::sub_socket(ctx, bound, "pose");

  std::vector<protocol::PoseMessage> poses;
  while (auto pose = test::recv_pose(sub, poses.empty() ? 5000 : 1500)) poses.push_back(*pose);
  ASSERT_EQ(child.wait(5000), 0) << child.log();

  // A paced replay restamps the samples with host time: the same shift for all.
  std::string error;
  auto reference = daemon::make_default_factory(daemon::bundled_skeleton_path())({"ik", {}}, error);
  ASSERT_TRUE(reference) << error;
  ASSERT_FALSE(poses.empty());
  std::int64_t shift = 0;
  if (paced)
    for (const auto& s : samples)
      if (s.role == Role::Head) {
        shift = poses[0].t_ns - s.t_ns;
        break;
      }
  const auto expected = test::expected_poses(samples, *reference, shift);
  ASSERT_EQ(poses.size(), expected.size()) << child.log();
  for (std::size_t i = 0; i < poses.size(); ++i) {
    ASSERT_EQ(poses[i].seq, i);
    test::expect_pose_equals(poses[i], expected[i], shift, i);
    if (paced) {
      // Host times: published after the sample's time (how soon after is bodyd-bench-latency's
      // "arrival -> published", docs/daemon.md "Benchmark").
      EXPECT_GE(poses[i].publish_t_ns, poses[i].t_ns);
    }
  }
  EXPECT_NE(child.log().find("every source has finished; " + std::to_string(poses.size()) + " poses published"),
            std::string::npos)
      << child.log();
}

TEST(BodydProcess, ReplaysEveryFrameOverTcpLoopback) { replay_end_to_end("tcp://127.0.0.1:0", false); }

TEST(BodydProcess, ReplaysEveryFrameOverIpcPaced) {
  test::TempDir dir;
  replay_end_to_end("ipc://" + (dir.path / "pose").string(), true);
}

TEST(BodydProcess, StopsCleanlyOnSigtermSigintAndShutdownRequest) {
  for (const char* how : {"SIGTERM", "SIGINT", "shutdown"}) {
    SCOPED_TRACE(how);
    test::TempDir dir;
    const auto endpoints_file = dir.path / "endpoints.json";
    // No source: the bundled recording, looped, forever.
    test::Child child({kBodyd, "--method", "ik", "--pub", "ipc://" + (dir.path / "pose").string(), "--control",
                       "ipc://" + (dir.path / "control").string(), "--endpoints-file", endpoints_file.string()},
                      dir.path / "stderr.txt");
    const auto endpoints = test::wait_endpoints(endpoints_file, 10000);
    ASSERT_TRUE(endpoints) << child.log();
    zmq::context_t ctx;
    auto sub = test::sub_socket(ctx, (*endpoints)["pub"], "pose");
    ASSERT_TRUE(test::recv_pose(sub, 5000)) << child.log();
    if (std::string(how) == "shutdown") {
      // A malformed request first: answered, and the daemon keeps running.
      auto bad = test::control_request(ctx, (*endpoints)["control"], "{\"cmd\":");
      ASSERT_TRUE(bad);
      EXPECT_EQ((*bad)["ok"], false);
      EXPECT_TRUE(test::recv_pose(sub, 2000));
      auto reply = test::control_request(ctx, (*endpoints)["control"], R"({"cmd":"shutdown"})");
      ASSERT_TRUE(reply);
      EXPECT_EQ((*reply)["ok"], true);
    } else {
      child.signal(std::string(how) == "SIGTERM" ? SIGTERM : SIGINT);
    }
    EXPECT_EQ(child.wait(3000), 0) << child.log();
    EXPECT_NE(child.log().find("stopped:"), std::string::npos) << child.log();
    EXPECT_NE(child.log().find("in a loop"), std::string::npos) << child.log();
    // Issue 20 item 8: a clean stop removes the ipc:// socket files it bound (libzmq leaves them).
    for (const char* file : {"pose", "control"})
      EXPECT_FALSE(std::filesystem::exists(std::filesystem::symlink_status(dir.path / file)))
          << file << " is still there after a clean stop";
  }
}

TEST(BodydProcess, ASubscriberSurvivesARestart) {
  test::TempDir dir;
  short_log(dir.path / "log.csv", 270);  // 1 s paced
  const auto endpoints_file = dir.path / "endpoints.json";
  auto run_daemon = [&](const std::string& pub) {
    return std::make_unique<test::Child>(
        bodyd_args({"--replay", (dir.path / "log.csv").string(), "--pub", pub, "--control", "none", "--exit-at-end",
                    "--wait-for-subscriber", "--endpoints-file", endpoints_file.string()}),
        dir.path / "stderr.txt");
  };
  auto first = run_daemon("tcp://127.0.0.1:0");
  const auto endpoints = test::wait_endpoints(endpoints_file, 10000);
  ASSERT_TRUE(endpoints) << first->log();
  const std::string endpoint = (*endpoints)["pub"];
  zmq::context_t ctx;
  auto sub = test::sub_socket(ctx, endpoint, "pose");
  std::uint64_t last_seq = 0;
  int before = 0;
  while (auto pose = test::recv_pose(sub, 1500)) last_seq = pose->seq, ++before;
  ASSERT_EQ(first->wait(5000), 0) << first->log();
  ASSERT_GT(before, 50);

  // Same endpoint again: the subscriber reconnects by itself; seq starting again is the sign.
  std::filesystem::remove(endpoints_file);
  auto second = run_daemon(endpoint);
  ASSERT_TRUE(test::wait_endpoints(endpoints_file, 10000)) << second->log();
  auto pose = test::recv_pose(sub, 5000);
  ASSERT_TRUE(pose) << "no pose after the restart\n" << second->log();
  EXPECT_LT(pose->seq, last_seq) << "a restart shows as seq going back";
  int after = 1;
  while (test::recv_pose(sub, 1500)) ++after;
  EXPECT_GT(after, 50);
  EXPECT_EQ(second->wait(5000), 0);
}

TEST(BodydProcess, ClearErrorsForRefusedEndpointsAndBadModels) {
  test::TempDir dir;
  {
    test::Child child({kBodyd, "--method", "ik", "--pub", "tcp://0.0.0.0:0", "--control", "none"},
                      dir.path / "remote.txt");
    EXPECT_EQ(child.wait(5000), 1);
    EXPECT_NE(child.log().find("--allow-remote"), std::string::npos) << child.log();
  }
  {
    std::ofstream(dir.path / "bad.safetensors") << "not a model";
    test::Child child({kBodyd, "--method", "diffusion", "--model", (dir.path / "bad.safetensors").string(), "--pub",
                       "ipc://" + (dir.path / "p").string(), "--control", "none"},
                      dir.path / "model.txt");
    EXPECT_EQ(child.wait(5000), 1);
    EXPECT_NE(child.log().find("bad.safetensors"), std::string::npos) << child.log();
    EXPECT_NE(child.log().find("--method ik"), std::string::npos) << child.log();
  }
  {
    test::Child child({kBodyd, "--no-such-flag"}, dir.path / "usage.txt");
    EXPECT_EQ(child.wait(5000), 2);  // a bad command line (docs/daemon.md, issue 11)
  }
  {
    test::Child child({kBodyd, "--gen-keys", (dir.path / "keys").string()}, dir.path / "keys.txt");
    EXPECT_EQ(child.wait(5000), 0) << child.log();
    EXPECT_TRUE(std::filesystem::exists(dir.path / "keys" / "server.secret"));
    EXPECT_TRUE(std::filesystem::exists(dir.path / "keys" / "server.public"));
  }
}

}  // namespace
}  // namespace bodyd
