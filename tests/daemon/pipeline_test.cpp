// The daemon in-process (the bodyd_daemon library with real sockets): poses equal an
// in-process reconstruction, a stalled subscriber does not slow it, CURVE, endpoint rules,
// the control socket, the output rate and device offsets.
#include "bodyd/daemon/daemon.h"
#include "bodyd/io/zmq/endpoint.h"
#include "bodyd/daemon/reconstructors.h"
#include "bodyd/motion/tracker_log.h"
#include "fake_reconstructor.h"
#include "../test_paths.h"
#include "pose_compare.h"
#include "zmq_helpers.h"

#include "bodyd/test/files.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <thread>

namespace bodyd {
namespace {

using daemon::Daemon;
using daemon::DaemonConfig;
using namespace std::chrono_literals;

// The daemon's info logs would drown the test output.
const bool kQuietLogs = (spdlog::set_level(spdlog::level::warn), true);

daemon::ReconstructorFactory fake_factory(int* calls = nullptr) {
  return [calls](const daemon::ModelChoice& choice, std::string& error) -> std::unique_ptr<Reconstructor> {
    if (calls) ++*calls;
    if (choice.model_path.filename() == "bad.safetensors") {
      error = choice.model_path.string() + ": not a bodyd model";
      return nullptr;
    }
    return std::make_unique<test::FakeReconstructor>();
  };
}

DaemonConfig base_config(const std::filesystem::path& log) {
  DaemonConfig c;
  c.sources = {"replay:" + log.string()};
  c.fast = true;
  c.exit_at_end = true;
  c.pub_endpoint = "tcp://127.0.0.1:0";
  c.control_endpoint = "none";
  c.wait_for_subscriber = true;
  c.send_hwm = 1'000'000;
  c.method = "ik";
  c.auto_calibrate = false;  // the references below are at the model's size (calibration_test.cpp tests it)
  return c;
}

// 90 synthetic samples written as dir/log.csv, replayed at their pace in a loop until stopped,
// without waiting for a subscriber.
DaemonConfig looping_config(const std::filesystem::path& dir) {
  write_tracker_log(dir / "log.csv", test::synthetic_samples(90));
  DaemonConfig c = base_config(dir / "log.csv");
  c.fast = false;
  c.exit_at_end = false;
  c.loop = true;
  c.wait_for_subscriber = false;
  return c;
}

zmq::socket_t subscriber(zmq::context_t& ctx, const std::string& endpoint, std::string_view topic = "pose",
                         int rcvhwm = 0) {
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, rcvhwm);
  sub.set(zmq::sockopt::subscribe, topic);
  sub.connect(endpoint);
  return sub;
}

TEST(Pipeline, EveryPoseArrivesInOrderAndEqualsTheInProcessReconstruction) {
  test::TempDir dir;
  const auto samples = test::synthetic_samples(400);
  write_tracker_log(dir.path / "log.csv", samples);

  Daemon d(base_config(dir.path / "log.csv"), fake_factory());
  ASSERT_EQ(d.start(), "");
  zmq::context_t ctx;
  auto sub = subscriber(ctx, d.pub_endpoint());
  std::thread runner([&] { EXPECT_EQ(d.run(), 0); });

  test::FakeReconstructor reference;
  const auto expected = test::expected_poses(samples, reference);
  ASSERT_EQ(expected.size(), 400u);
  for (std::size_t i = 0; i < expected.size(); ++i) {
    auto pose = test::recv_pose(sub, 5000);
    ASSERT_TRUE(pose) << "pose " << i << " did not arrive";
    EXPECT_EQ(pose->seq, i);
    test::expect_pose_equals(*pose, expected[i], 0, i);
  }
  runner.join();
  EXPECT_FALSE(test::recv_pose(sub, 100)) << "more poses than expected";
}

TEST(Pipeline, IkPosesEqualTheInProcessIkReconstruction) {
  test::TempDir dir;
  const auto samples = read_tracker_log(daemon::bundled_recording_path()).samples;
  write_tracker_log(dir.path / "log.csv", std::vector<TrackerSample>(samples.begin(), samples.begin() + 900));
  const auto factory = daemon::make_default_factory(daemon::bundled_skeleton_path());
  Daemon d(base_config(dir.path / "log.csv"), factory);
  ASSERT_EQ(d.start(), "");
  zmq::context_t ctx;
  auto sub = subscriber(ctx, d.pub_endpoint());
  std::thread runner([&] { EXPECT_EQ(d.run(), 0); });

  std::string error;
  auto reference = factory({"ik", {}}, error);
  ASSERT_TRUE(reference) << error;
  const auto expected = test::expected_poses({samples.begin(), samples.begin() + 900}, *reference);
  ASSERT_EQ(expected.size(), 300u);
  for (std::size_t i = 0; i < expected.size(); ++i) {
    auto pose = test::recv_pose(sub, 5000);
    ASSERT_TRUE(pose) << "pose " << i;
    EXPECT_EQ(pose->seq, i);
    test::expect_pose_equals(*pose, expected[i], 0, i);
  }
  runner.join();
}

// How long a fast replay may take: a Debug build with AddressSanitizer (make sanitize) runs it
// about five times slower (30.4 s measured for 25,000 poses, against the 30 s of other builds).
#if defined(__SANITIZE_ADDRESS__)
constexpr int kReplayLimitS = 180;
#else
constexpr int kReplayLimitS = 30;
#endif

// Runs a fast replay of `samples` with ik; returns the time from the first to the last
// published pose, and the number published. With `stalled`, a subscriber that never reads.
std::pair<double, std::uint64_t> timed_run(const std::filesystem::path& log, bool stalled, int* received_by_stalled) {
  DaemonConfig c = base_config(log);
  c.send_hwm = 10;
  Daemon d(c, daemon::make_default_factory(daemon::bundled_skeleton_path()));
  std::int64_t first = 0, last = 0;
  d.set_frame_observer([&](const daemon::FrameTiming& t) {
    if (first == 0) first = t.published_ns;
    last = t.published_ns;
  });
  EXPECT_EQ(d.start(), "");
  zmq::context_t ctx;
  // A stalled subscriber: ZeroMQ itself holds at most one pose for it, and it never reads.
  auto sub = subscriber(ctx, d.pub_endpoint(), "pose", stalled ? 1 : 0);
  std::atomic<bool> done{false};
  int received = 0;
  std::thread reader;
  if (!stalled)
    reader = std::thread([&] {
      while (!done.load())
        if (test::recv_pose(sub, 20)) ++received;
    });
  std::atomic<bool> finished{false};
  std::thread runner([&] {
    d.run();
    finished.store(true);
  });
  // A publisher that blocked on the stalled subscriber would never finish.
  for (int i = 0; i < kReplayLimitS * 100 && !finished.load(); ++i) std::this_thread::sleep_for(10ms);
  EXPECT_TRUE(finished.load()) << "the replay did not finish within " << kReplayLimitS << " s";
  d.request_stop();
  runner.join();
  done.store(true);
  if (reader.joinable()) reader.join();
  if (stalled) {
    while (test::recv_pose(sub, 200)) ++received;
    *received_by_stalled = received;
  }
  return {static_cast<double>(last - first) / 1e9, d.status()["frames_out"].get<std::uint64_t>()};
}

TEST(Pipeline, AStalledSubscriberDoesNotSlowTheDaemon) {
  test::TempDir dir;
  const int frames = 25000;  // more than the TCP buffers hold (about 7000 poses here)
  write_tracker_log(dir.path / "log.csv", test::synthetic_samples(frames));
  int ignored = 0, stalled_received = 0;
  const auto [reading_s, reading_out] = timed_run(dir.path / "log.csv", false, &ignored);
  const auto [stalled_s, stalled_out] = timed_run(dir.path / "log.csv", true, &stalled_received);
  EXPECT_EQ(reading_out, static_cast<std::uint64_t>(frames));
  EXPECT_EQ(stalled_out, static_cast<std::uint64_t>(frames));  // every pose was sent, none waited
  // The stalled subscriber really was stalled: ZeroMQ dropped most of its poses.
  EXPECT_LT(stalled_received, frames / 2);
  std::printf("fast replay of %d poses: %.3f s with a reading subscriber, %.3f s with a stalled one "
              "(which got %d)\n", frames, reading_s, stalled_s, stalled_received);
  // A publisher that waited for the subscriber would not have finished at all (above). How much
  // a stalled subscriber costs each pose is measured by `bodyd-bench-latency --stalled-subscriber`
  // (docs/daemon.md, "Benchmark"), not asserted here.
}

// The endpoints file goes through a private temporary file, as every file bodyd keeps
// (docs/reliability.md, "Persisted files"): it was written through FILE.tmp with std::ofstream,
// which followed a symbolic link there (and waited for ever on a FIFO there).
TEST(Pipeline, TheEndpointsFileNeverFollowsALinkAtTheOldTemporaryName) {
  test::TempDir dir;
  DaemonConfig c = looping_config(dir.path);
  c.endpoints_file = (dir.path / "endpoints.json").string();
  ASSERT_TRUE(test::write_file(dir.path / "victim", "keep"));
  std::filesystem::create_symlink(dir.path / "victim", dir.path / "endpoints.json.tmp");
  Daemon d(c, fake_factory());
  ASSERT_EQ(d.start(), "");
  d.stop();
  EXPECT_EQ(test::read_file(dir.path / "victim"), "keep");
  EXPECT_TRUE(std::filesystem::is_symlink(dir.path / "endpoints.json.tmp"));
  ASSERT_TRUE(std::filesystem::is_regular_file(std::filesystem::symlink_status(c.endpoints_file)));
  const nlohmann::json endpoints = nlohmann::json::parse(test::read_file(c.endpoints_file), nullptr, false);
  EXPECT_EQ(endpoints.value("pub", ""), d.pub_endpoint()) << endpoints.dump();
}

TEST(Pipeline, CurveClientWithTheServerKeyReceivesOthersDoNot) {
  test::TempDir dir;
  daemon::CurveKeyPair server;
  ASSERT_EQ(daemon::generate_curve_keys(dir.path / "keys", server), "");
  DaemonConfig c = looping_config(dir.path);
  c.curve_secret_key_file = (dir.path / "keys" / "server.secret").string();
  Daemon d(c, fake_factory());
  ASSERT_EQ(d.start(), "");
  EXPECT_EQ(d.curve_public_key(), server.public_key);
  std::thread runner([&] { d.run(); });

  zmq::context_t ctx;
  auto make_client = [&](const std::string& server_key) {
    zmq::socket_t sub(ctx, zmq::socket_type::sub);
    sub.set(zmq::sockopt::linger, 0);
    if (!server_key.empty()) {
      char pub[41], sec[41];
      zmq_curve_keypair(pub, sec);
      sub.set(zmq::sockopt::curve_serverkey, server_key);
      sub.set(zmq::sockopt::curve_publickey, std::string(pub));
      sub.set(zmq::sockopt::curve_secretkey, std::string(sec));
    }
    sub.set(zmq::sockopt::subscribe, "pose");
    sub.connect(d.pub_endpoint());
    return sub;
  };
  auto good = make_client(server.public_key);
  auto plain = make_client("");
  char other_pub[41], other_sec[41];
  zmq_curve_keypair(other_pub, other_sec);
  auto wrong = make_client(other_pub);
  EXPECT_TRUE(test::recv_pose(good, 3000)) << "the client with the server key received nothing";
  EXPECT_FALSE(test::recv_pose(plain, 700)) << "a client without CURVE received poses";
  EXPECT_FALSE(test::recv_pose(wrong, 300)) << "a client with the wrong server key received poses";
  d.request_stop();
  runner.join();
}

TEST(Pipeline, RemoteBindRefusedUnlessAllowedAndBusyEndpointsExplained) {
  test::TempDir dir;
  write_tracker_log(dir.path / "log.csv", test::synthetic_samples(3));
  {
    DaemonConfig c = base_config(dir.path / "log.csv");
    c.pub_endpoint = "tcp://0.0.0.0:0";
    Daemon d(c, fake_factory());
    const std::string e = d.start();
    EXPECT_NE(e.find("--allow-remote"), std::string::npos) << e;
    c.allow_remote = true;
    Daemon allowed(c, fake_factory());
    EXPECT_EQ(allowed.start(), "");
    allowed.stop();
  }
  {
    DaemonConfig c = base_config(dir.path / "log.csv");
    Daemon first(c, fake_factory());
    ASSERT_EQ(first.start(), "");
    c.pub_endpoint = first.pub_endpoint();
    Daemon second(c, fake_factory());
    const std::string e = second.start();
    EXPECT_NE(e.find("address in use (another bodyd running?"), std::string::npos) << e;
    EXPECT_NE(e.find(first.pub_endpoint()), std::string::npos) << e;
  }
  {
    DaemonConfig c = base_config(dir.path / "log.csv");
    c.pub_endpoint = "ipc://" + (dir.path / "ipc" / "pose").string();
    Daemon first(c, fake_factory());
    ASSERT_EQ(first.start(), "");
    Daemon second(c, fake_factory());
    const std::string e = second.start();
    EXPECT_NE(e.find("another bodyd running?"), std::string::npos) << e;
  }
  {
    DaemonConfig c = base_config(dir.path / "log.csv");
    c.sources = {"replay:" + (dir.path / "missing.csv").string()};
    Daemon d(c, fake_factory());
    EXPECT_NE(d.start().find("missing.csv"), std::string::npos);
  }
}

class ControlSocket : public ::testing::Test {
 protected:
  void SetUp() override {
    DaemonConfig c = looping_config(dir.path);
    c.control_endpoint = "ipc://" + (dir.path / "control").string();
    c.pub_endpoint = "ipc://" + (dir.path / "pose").string();
    daemon_ = std::make_unique<Daemon>(c, fake_factory(&factory_calls));
    ASSERT_EQ(daemon_->start(), "");
    runner = std::thread([&] { exit_code = daemon_->run(); });
  }
  void TearDown() override {
    daemon_->request_stop();
    if (runner.joinable()) runner.join();
  }
  nlohmann::json request(const std::string& text) {
    auto reply = test::control_request(ctx, daemon_->control_endpoint(), text);
    EXPECT_TRUE(reply) << "no reply to " << text;
    return reply ? *reply : nlohmann::json();
  }

  test::TempDir dir;
  zmq::context_t ctx;
  std::unique_ptr<Daemon> daemon_;
  std::thread runner;
  int exit_code = -1;
  int factory_calls = 0;
};

TEST_F(ControlSocket, StatusSkeletonCalibrateReloadAndMalformedRequests) {
  auto sub = subscriber(ctx, daemon_->pub_endpoint(), "");
  ASSERT_TRUE(test::recv_pose(sub, 3000));

  nlohmann::json status = request(R"({"cmd":"status"})");
  EXPECT_EQ(status["ok"], true);
  EXPECT_EQ(status["method"], "fake");
  ASSERT_EQ(status["sources"].size(), 1u);
  EXPECT_EQ(status["sources"][0]["connected"], true);
  EXPECT_GT(status["samples_in"].get<int>(), 0);
  EXPECT_GE(status["subscriptions"].get<int>(), 1);
  for (const char* key : {"uptime_s", "frames_out", "samples_dropped", "reconstruct_us", "latency_us", "pub",
                          "head_height_m", "skeleton_id", "queue_depth"})
    EXPECT_TRUE(status.contains(key)) << key;

  // The skeleton reply is the skeleton message's content.
  nlohmann::json skel = request(R"({"cmd":"skeleton"})");
  ASSERT_EQ(skel["ok"], true);
  auto bytes = test::recv_topic(sub, protocol::kSkeletonTopic, 2000);
  ASSERT_TRUE(bytes);
  protocol::SkeletonMessage msg;
  ASSERT_TRUE(protocol::decode_skeleton(*bytes, msg).ok());
  EXPECT_EQ(skel["skeleton_id"], msg.skeleton_id);
  EXPECT_EQ(skel["names"], nlohmann::json(msg.names));
  EXPECT_EQ(skel["parents"], nlohmann::json(msg.parents));
  EXPECT_FLOAT_EQ(skel["offsets_m"][1][1].get<float>(), msg.offsets_m[1][1]);

  // Malformed requests: an error each, and the daemon keeps going.
  for (const char* bad : {"garbage", "{}", R"({"cmd":3})", R"({"cmd":"fly"})", R"({"cmd":"calibrate","user_height_m":"x"})"}) {
    nlohmann::json reply = request(bad);
    EXPECT_EQ(reply["ok"], false) << bad;
    EXPECT_TRUE(reply["error"].is_string()) << bad;
  }
  {
    zmq::socket_t req(ctx, zmq::socket_type::req);
    req.set(zmq::sockopt::rcvtimeo, 3000);
    req.connect(daemon_->control_endpoint());
    req.send(zmq::str_buffer("{\"cmd\":"), zmq::send_flags::sndmore);
    req.send(zmq::str_buffer("\"status\"}"));
    zmq::message_t reply;
    ASSERT_TRUE(req.recv(reply));
    EXPECT_NE(reply.to_string().find("one frame"), std::string::npos) << reply.to_string();
  }

  // Calibrate: new skeleton id in the reply, in a skeleton message and in the poses.
  nlohmann::json cal = request(R"({"cmd":"calibrate","head_height_m":1.8})");
  ASSERT_EQ(cal["ok"], true) << cal;
  EXPECT_DOUBLE_EQ(cal["head_height_m"].get<double>(), 1.8);
  EXPECT_NE(cal["skeleton_id"], skel["skeleton_id"]);
  bool seen_new_skeleton = false;
  for (int i = 0; i < 50 && !seen_new_skeleton; ++i) {
    auto b = test::recv_topic(sub, protocol::kSkeletonTopic, 1500);
    ASSERT_TRUE(b);
    ASSERT_TRUE(protocol::decode_skeleton(*b, msg).ok());
    seen_new_skeleton = msg.skeleton_id == cal["skeleton_id"];
  }
  EXPECT_TRUE(seen_new_skeleton);
  EXPECT_NEAR(msg.offsets_m[1][1], 0.9f * 1.8f / 1.5f, 1e-6);
  std::optional<protocol::PoseMessage> pose;
  for (int i = 0; i < 100; ++i) {
    pose = test::recv_pose(sub, 1000);
    ASSERT_TRUE(pose);
    if (pose->skeleton_id == cal["skeleton_id"]) break;
  }
  EXPECT_EQ(pose->skeleton_id, cal["skeleton_id"]);
  EXPECT_TRUE(pose->flags & protocol::kFlagHeightCalibrated);

  // From the head: the synthetic head circles at walking speed, so it is refused (a moving head's
  // height is not the standing height; issue 16) and the height stays. A still head is taken:
  // CalibrateFromHead.TakesAStillHead (device_frames_test.cpp).
  cal = request(R"({"cmd":"calibrate","from":"head"})");
  EXPECT_EQ(cal["ok"], false) << cal;
  EXPECT_NE(cal.value("error", "").find("the head is moving"), std::string::npos) << cal;

  // Reload: a file outside the models directory is refused before anything reads it (issue 11),
  // the old model is kept; a reload of the configured model asks the factory again.
  const int calls = factory_calls;
  nlohmann::json reload = request(R"({"cmd":"reload-model","path":"/x/bad.safetensors"})");
  EXPECT_EQ(reload["ok"], false);
  EXPECT_NE(reload["error"].get<std::string>().find("bad.safetensors"), std::string::npos) << reload;
  EXPECT_EQ(factory_calls, calls);
  reload = request(R"({"cmd":"reload-model"})");
  EXPECT_EQ(reload["ok"], true) << reload;
  EXPECT_EQ(factory_calls, calls + 1);
  EXPECT_NEAR(reload["head_height_m"].get<double>(), 1.8, 1e-9);  // the calibration carries over
  EXPECT_TRUE(test::recv_pose(sub, 2000));

  EXPECT_EQ(request(R"({"cmd":"status"})")["ok"], true);
  EXPECT_EQ(request(R"({"cmd":"shutdown"})")["ok"], true);
  runner.join();
  EXPECT_EQ(exit_code, 0);
}

TEST(Pipeline, OutputRateLimitAndDeviceOffsets) {
  test::TempDir dir;
  const auto samples = test::synthetic_samples(300);  // 90 Hz
  write_tracker_log(dir.path / "log.csv", samples);
  DaemonConfig c = base_config(dir.path / "log.csv");
  c.rate_hz = 30;
  daemon::DeviceOffset head_offset;
  head_offset.position_m = Vec3(0, 0, 0.1);
  c.offsets[0] = head_offset;
  Daemon d(c, fake_factory());
  ASSERT_EQ(d.start(), "");
  zmq::context_t ctx;
  auto sub = subscriber(ctx, d.pub_endpoint());
  std::thread runner([&] { d.run(); });
  std::vector<protocol::PoseMessage> poses;
  while (auto p = test::recv_pose(sub, 1000)) poses.push_back(*p);
  runner.join();
  ASSERT_EQ(poses.size(), 100u);  // every third head sample
  for (std::size_t i = 1; i < poses.size(); ++i) EXPECT_EQ(poses[i].t_ns - poses[i - 1].t_ns, 3 * 11'111'111);
  // The Head joint (index 2 of the fake) is the head sample moved by R * offset.
  const TrackerSample& h = samples[0];
  const Vec3 expected = h.position_m + h.rotation * Vec3(0, 0, 0.1);
  EXPECT_FLOAT_EQ(poses[0].joints[2].position_m[0], static_cast<float>(expected.x()));
  EXPECT_FLOAT_EQ(poses[0].joints[2].position_m[2], static_cast<float>(expected.z()));
  EXPECT_TRUE(poses[0].flags & protocol::kFlagOffsetsCalibrated);
}

}  // namespace
}  // namespace bodyd
