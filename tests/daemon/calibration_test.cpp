// The daemon's auto calibration (docs/daemon.md, "Calibration") on replays of scaled logs, a
// manual calibration winning over it, the "auto_calibrate" and "filter" config keys reaching
// the daemon and the reconstructor, and every ZeroMQ output sending each skeleton before the
// poses that name it.
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/daemon.h"
#include "bodyd/daemon/reconstructors.h"
#include "bodyd/inference/diffusion.h"
#include "bodyd/inference/ik.h"
#include "bodyd/inference/model_file.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/tracker_log.h"
#include "bodyd/simulators/tracker_sim.h"
#include "../test_paths.h"
#include "zmq_helpers.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <fstream>
#include <set>
#include <sstream>
#include <thread>

namespace bodyd {
namespace {

using daemon::Daemon;
using daemon::DaemonConfig;
using nlohmann::json;
using namespace std::chrono_literals;

const bool kQuietLogs = (spdlog::set_level(spdlog::level::warn), true);

// The trackers of a fixture clip acted by a user `scale` x the performer's size: every position
// scaled about the origin (the floor stays at y = 0), as bodyd-eval --body-scale scales a clip.
std::vector<TrackerSample> scaled_samples(const std::filesystem::path& bvh, double scale, double noise_mm = 0.0) {
  SimOptions o;
  o.rate_hz = 90.0;
  o.position_noise_mm = noise_mm;
  std::vector<TrackerSample> samples = simulate_trackers(read_bvh(bvh), o);
  for (TrackerSample& s : samples) s.position_m *= scale;
  return samples;
}

DaemonConfig replay_config(const std::filesystem::path& log, const std::filesystem::path& dir) {
  DaemonConfig c;
  c.sources = {"replay:" + log.string()};
  c.fast = true;
  c.pub_endpoint = "tcp://127.0.0.1:0";
  c.control_endpoint = "ipc://" + (dir / "control").string();
  c.wait_for_subscriber = true;
  c.send_hwm = 1'000'000;
  c.method = "ik";
  return c;
}

// Receives every pose of the replay (until none comes for a while).
std::vector<protocol::PoseMessage> all_poses(zmq::socket_t& sub) {
  std::vector<protocol::PoseMessage> poses;
  while (auto p = test::recv_pose(sub, poses.empty() ? 10000 : 1500)) poses.push_back(*p);
  return poses;
}

// `bvh`'s trackers scaled by `scale` (scaled_samples), written as dir/scaled.csv.
std::vector<TrackerSample> write_scaled(const std::filesystem::path& dir, const std::filesystem::path& bvh, double scale) {
  std::vector<TrackerSample> samples = scaled_samples(bvh, scale);
  write_tracker_log(dir / "scaled.csv", samples);
  return samples;
}

std::size_t head_count(const std::vector<TrackerSample>& samples) {
  std::size_t n = 0;
  for (const TrackerSample& s : samples) n += s.role == Role::Head;
  return n;
}

TEST(AutoCalibration, AScaledReplayCalibratesFromTheStillStartAndAManualCalibrationReplacesIt) {
  test::TempDir dir;
  const std::filesystem::path bow = test::fixtures() / "bow_30.bvh";
  const auto samples = write_scaled(dir.path, bow, 0.8);
  DaemonConfig c = replay_config(dir.path / "scaled.csv", dir.path);
  c.record_trackers_file = (dir.path / "recorded.csv").string();
  Daemon d(c, daemon::make_default_factory(bow));
  ASSERT_EQ(d.start(), "");
  EXPECT_EQ(d.status()["auto_calibration"], "waiting");
  EXPECT_EQ(d.status()["calibration_source"], "none");
  const double model_height_m = d.status()["head_height_m"].get<double>();
  zmq::context_t ctx;
  auto sub = test::sub_socket(ctx, d.pub_endpoint(), "pose");
  std::thread runner([&] { d.run(); });
  const auto poses = all_poses(sub);

  ASSERT_EQ(poses.size(), head_count(samples));
  // The bow starts standing: calibrated half a second in, the poses after it say so.
  const json status = d.status();
  EXPECT_EQ(status["calibration_source"], "auto");
  EXPECT_EQ(status["auto_calibration"], "still");
  EXPECT_EQ(status["height_calibrated"], true);
  const double truth_m = 0.8 * standing_head_height_m(read_bvh(bow).skeleton);
  EXPECT_NEAR(status["head_height_m"].get<double>() / truth_m, 1.0, 0.02) << "model's: " << model_height_m;
  EXPECT_FALSE(poses.front().flags & protocol::kFlagHeightCalibrated);
  EXPECT_TRUE(poses.back().flags & protocol::kFlagHeightCalibrated);
  EXPECT_NE(poses.front().skeleton_id, poses.back().skeleton_id);
  EXPECT_EQ(poses.back().skeleton_id, status["skeleton_id"]);
  int calibrated_at = -1;
  for (std::size_t i = 0; i < poses.size() && calibrated_at < 0; ++i)
    if (poses[i].flags & protocol::kFlagHeightCalibrated) calibrated_at = static_cast<int>(i);
  EXPECT_NEAR(calibrated_at, 45, 1);  // 0.5 s at 90 Hz

  // A manual calibration replaces it.
  const auto reply = test::control_request(ctx, d.control_endpoint(), R"({"cmd":"calibrate","head_height_m":1.3})");
  ASSERT_TRUE(reply);
  EXPECT_EQ((*reply)["ok"], true) << *reply;
  EXPECT_EQ((*reply)["calibration_source"], "control");
  EXPECT_EQ((*reply)["auto_calibration"], "still");
  EXPECT_DOUBLE_EQ(d.status()["head_height_m"].get<double>(), 1.3);
  d.request_stop();
  runner.join();
  d.stop();  // writes the rest of the recording

  // The recording says what happened, as comments.
  std::ifstream in(c.record_trackers_file);
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_NE(text.str().find(": calibrate head_height_m "), std::string::npos);
  EXPECT_NE(text.str().find("(auto: the head held still at "), std::string::npos);
}

TEST(AutoCalibration, AManualOrConfiguredHeightWinsAndTheFlagTurnsItOff) {
  test::TempDir dir;
  const std::filesystem::path walk = test::fixtures() / "walk_60.bvh";
  const auto samples = write_scaled(dir.path, walk, 1.2);
  zmq::context_t ctx;
  // Each way: the configuration, the calibration source and auto state after the replay, and the
  // standing head height then (0: the model's own).
  struct Case {
    const char* name;
    std::function<void(DaemonConfig&)> configure;
    const char* request;  // sent before the replay starts, or null
    const char* source;
    const char* auto_state;
    double height_m;
  };
  const std::vector<Case> cases{
      {"auto (fallback: the walk is never still)", [](DaemonConfig&) {}, nullptr, "auto", "fallback", -1.0},
      {"control socket first", [](DaemonConfig&) {}, R"({"cmd":"calibrate","head_height_m":1.9})", "control",
       "superseded", 1.9},
      {"configured", [](DaemonConfig& c) { c.head_height_m = 1.7; }, nullptr, "config", "superseded", 1.7},
      {"--no-auto-calibrate", [](DaemonConfig& c) { c.auto_calibrate = false; }, nullptr, "none", "off", 0.0},
  };
  for (const Case& k : cases) {
    SCOPED_TRACE(k.name);
    DaemonConfig c = replay_config(dir.path / "scaled.csv", dir.path);
    k.configure(c);
    Daemon d(c, daemon::make_default_factory(walk));
    ASSERT_EQ(d.start(), "");
    const double model_height_m = d.status()["head_height_m"].get<double>();
    std::thread runner([&] { d.run(); });
    if (k.request) {
      // The control socket is served while the daemon waits for its first subscriber.
      const auto reply = test::control_request(ctx, d.control_endpoint(), k.request);
      ASSERT_TRUE(reply);
      EXPECT_EQ((*reply)["calibration_source"], "control") << *reply;
    }
    auto sub = test::sub_socket(ctx, d.pub_endpoint(), "pose");
    const auto poses = all_poses(sub);
    EXPECT_EQ(poses.size(), head_count(samples));
    const json status = d.status();
    EXPECT_EQ(status["calibration_source"], k.source);
    EXPECT_EQ(status["auto_calibration"], k.auto_state);
    const double h = status["head_height_m"].get<double>();
    if (k.height_m > 0.0) EXPECT_DOUBLE_EQ(h, k.height_m);
    else if (k.height_m == 0.0) EXPECT_DOUBLE_EQ(h, model_height_m);
    else EXPECT_NEAR(h / (1.2 * standing_head_height_m(read_bvh(walk).skeleton)), 1.0, 0.02);
    EXPECT_EQ(status["height_calibrated"], std::string(k.source) != "none");
    d.request_stop();
    runner.join();
  }
}

TEST(DaemonConfigKeys, AutoCalibrateAndFilterParseValidateAndPrint) {
  DaemonConfig c;
  const json text = json::parse(R"({"auto_calibrate": false, "filter": {"enabled": false,
      "min_cutoff_hz": 0.5, "beta_per_m_s": 10, "d_cutoff_hz": 2, "rot_min_cutoff_hz": 0.7, "rot_beta_per_rad_s": 3,
      "head_correction_cutoff_hz": 2.5, "anchor_cutoff_hz": 0.75, "hand_reach_slack_m": 0.03,
      "arm_soft_zone_m": 0.02}})");
  ASSERT_EQ(daemon::apply_config_json(text, "c.json", c), "");
  EXPECT_FALSE(c.auto_calibrate);
  const json printed = daemon::config_to_json(c);  // each key where it was read (a value in another key's member shows)
  for (const auto& [key, value] : text["filter"].items()) EXPECT_EQ(printed["filter"][key], value) << key;
  EXPECT_FALSE(c.filter.enabled);
  EXPECT_DOUBLE_EQ(c.filter.arm_soft_zone_m, 0.02);
  EXPECT_EQ(daemon::validate_config(c), "");
  // Printed as read: --print-config's output loads back to the same values.
  DaemonConfig back;
  ASSERT_EQ(daemon::apply_config_json(daemon::config_to_json(c), "printed", back), "");
  EXPECT_EQ(daemon::config_to_json(back), daemon::config_to_json(c));

  // Errors name the file, the key and what is expected.
  const auto error = [](const char* text) {
    DaemonConfig x;
    std::string e = daemon::apply_config_json(json::parse(text), "c.json", x);
    return e.empty() ? daemon::validate_config(x) : e;
  };
  std::string e = error(R"({"auto_calibrate": "yes"})");
  EXPECT_NE(e.find("c.json: auto_calibrate: expected true or false"), std::string::npos) << e;
  e = error(R"({"filter": {"min_cutoff": 1}})");
  EXPECT_NE(e.find("c.json: filter.min_cutoff: unknown key (expected enabled, min_cutoff_hz"), std::string::npos) << e;
  e = error(R"({"filter": {"beta_per_m_s": "fast"}})");
  EXPECT_NE(e.find("c.json: filter.beta_per_m_s: expected a number"), std::string::npos) << e;
  e = error(R"({"filter": 3})");
  EXPECT_NE(e.find("c.json: filter: expected an object"), std::string::npos) << e;
  e = error(R"({"filter": {"min_cutoff_hz": 0}})");
  EXPECT_NE(e.find("min_cutoff_hz must be > 0"), std::string::npos) << e;
  EXPECT_NE(e.find("docs/daemon.md"), std::string::npos) << e;
  e = error(R"({"filter": {"beta_per_m_s": -1}})");
  EXPECT_NE(e.find("beta_per_m_s must be >= 0"), std::string::npos) << e;
  e = error(R"({"filter": {"head_correction_cutoff_hz": -4}})");
  EXPECT_NE(e.find("filter head_correction_cutoff_hz must be > 0, not -4"), std::string::npos) << e;
  e = error(R"({"filter": {"anchor_cutoff_hz": -0.5}})");
  EXPECT_NE(e.find("filter anchor_cutoff_hz must be >= 0, not -0.5"), std::string::npos) << e;
  e = error(R"({"filter": {"hand_reach_slack_m": -1}})");
  EXPECT_NE(e.find("filter hand_reach_slack_m must be >= 0, not -1"), std::string::npos) << e;
  e = error(R"({"filter": {"arm_soft_zone_m": -0.01}})");
  EXPECT_NE(e.find("filter arm_soft_zone_m must be >= 0, not -0.01"), std::string::npos) << e;

  // The flags.
  DaemonConfig f;
  const char* argv[] = {"bodyd", "--no-auto-calibrate", "--no-filter"};
  const auto cli = daemon::parse_command_line(3, argv, f);
  EXPECT_EQ(cli.action, daemon::CliResult::Action::Run);
  EXPECT_FALSE(f.auto_calibrate);
  EXPECT_FALSE(f.filter.enabled);
  DaemonConfig g;
  const char* defaults[] = {"bodyd"};
  (void)daemon::parse_command_line(1, defaults, g);
  EXPECT_TRUE(g.auto_calibrate);
  EXPECT_TRUE(g.filter.enabled);
}

// The "filter" values reach the diffusion reconstructor the daemon's factory makes: on noisy
// trackers its poses equal those of a reconstructor built with the same filter options, and
// differ from those with the default filter.
TEST(DaemonConfigKeys, FilterValuesReachTheReconstructor) {
  const std::filesystem::path model = test::fixtures() / "tiny_model.safetensors";
  const auto samples = scaled_samples(test::fixtures() / "walk_60.bvh", 1.0, 5.0);
  OneEuroOptions filter;
  filter.min_cutoff_hz = 0.3;
  filter.beta_per_m_s = 2.0;
  filter.d_cutoff_hz = 3.0;
  ReconstructorOptions options;
  options.filter = filter;
  std::string error;
  const auto made = daemon::make_default_factory(daemon::bundled_skeleton_path(), options)({"diffusion", model}, error);
  ASSERT_TRUE(made) << error;
  DiffusionOptions same, other;
  same.filter = filter;
  const auto shared = inference::load_model(model);
  DiffusionReconstructor with_same(shared, same), with_default(shared, other);
  BodyPose a, b, o;
  double max_same = 0.0, max_other = 0.0;
  for (const TrackerSample& s : samples) {
    made->push(s);
    with_same.push(s);
    with_default.push(s);
    if (s.role != Role::Head) continue;
    const bool ok = made->reconstruct(s.t_ns, a);
    ASSERT_EQ(ok, with_same.reconstruct(s.t_ns, b));
    ASSERT_EQ(ok, with_default.reconstruct(s.t_ns, o));
    if (!ok) continue;
    for (std::size_t j = 0; j < a.global.positions.size(); ++j) {
      max_same = std::max(max_same, (a.global.positions[j] - b.global.positions[j]).norm());
      max_other = std::max(max_other, (a.global.positions[j] - o.global.positions[j]).norm());
    }
  }
  EXPECT_EQ(max_same, 0.0);
  EXPECT_GT(max_other, 1e-4);
}


// One message of any topic (topic, bytes) within timeout_ms; nullopt on timeout.
std::optional<std::pair<std::string, std::vector<std::uint8_t>>> recv_any(zmq::socket_t& sub, int timeout_ms) {
  zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
  if (zmq::poll(&item, 1, std::chrono::milliseconds(timeout_ms)) == 0) return std::nullopt;
  zmq::message_t topic, message;
  if (!sub.recv(topic) || !topic.more() || !sub.recv(message)) return std::nullopt;
  const auto* p = static_cast<const std::uint8_t*>(message.data());
  return std::make_pair(topic.to_string(), std::vector<std::uint8_t>(p, p + message.size()));
}

// docs/protocol.md: a pose names its skeleton by skeleton_id, and the skeleton is sent whenever it
// changes. A subscriber of an `--output zmq:` endpoint (not --pub) gets the skeleton before the
// first pose, and the auto calibration's new skeleton (half a second into the 0.8-scaled bow)
// before the first pose that names it: a fast replay sends all its poses well within the
// skeleton's once-a-second repeat, so only a skeleton sent on change can come first.
TEST(ZmqOutputs, AnOutputZmqSubscriberGetsEachSkeletonBeforeThePosesNamingIt) {
  test::TempDir dir;
  const std::filesystem::path bow = test::fixtures() / "bow_30.bvh";
  const auto samples = write_scaled(dir.path, bow, 0.8);
  DaemonConfig c = replay_config(dir.path / "scaled.csv", dir.path);
  const std::string extra = "ipc://" + (dir.path / "extra").string();
  c.outputs = {"zmq:" + extra};
  Daemon d(c, daemon::make_default_factory(bow));
  ASSERT_EQ(d.start(), "");
  zmq::context_t ctx;
  auto sub = test::sub_socket(ctx, extra);  // every topic
  std::thread runner([&] { d.run(); });
  // While the daemon waits for a subscriber on --pub, the extra output sends its skeleton to this
  // subscriber: once it has arrived, this subscription is in place before the first pose.
  std::set<std::uint32_t> known;
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (known.empty() && std::chrono::steady_clock::now() < deadline) {
    const auto m = recv_any(sub, 100);
    if (!m) continue;
    ASSERT_EQ(m->first, "skeleton") << "a pose before any skeleton";
    protocol::SkeletonMessage skeleton;
    ASSERT_TRUE(protocol::decode_skeleton(m->second, skeleton).ok());
    known.insert(skeleton.skeleton_id);
  }
  ASSERT_FALSE(known.empty()) << "no skeleton on the --output zmq: endpoint while the daemon waits";
  auto pub_sub = test::sub_socket(ctx, d.pub_endpoint(), "pose");  // starts the replay

  // Until no pose has come for a while (the skeleton keeps coming once a second).
  std::size_t poses = 0;
  std::set<std::uint32_t> named;
  auto last_pose = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - last_pose < (poses == 0 ? 10000ms : 1500ms)) {
    const auto m = recv_any(sub, 100);
    if (!m) continue;
    if (m->first == "skeleton") {
      protocol::SkeletonMessage skeleton;
      ASSERT_TRUE(protocol::decode_skeleton(m->second, skeleton).ok());
      known.insert(skeleton.skeleton_id);
      continue;
    }
    ASSERT_EQ(m->first, "pose");
    protocol::PoseMessage pose;
    ASSERT_TRUE(protocol::decode_pose(m->second, pose).ok());
    ASSERT_TRUE(known.count(pose.skeleton_id)) << "pose " << poses << " (seq " << pose.seq << ") names skeleton "
                                               << pose.skeleton_id << " before it was sent";
    named.insert(pose.skeleton_id);
    ++poses;
    last_pose = std::chrono::steady_clock::now();
  }
  EXPECT_EQ(poses, head_count(samples));
  EXPECT_EQ(named.size(), 2u) << "the auto calibration should have changed the skeleton once";
  EXPECT_EQ(d.status()["calibration_source"], "auto");
  d.request_stop();
  runner.join();
}

}  // namespace
}  // namespace bodyd
