// bodyd --output vrchat against an OSC implementation nobody here wrote: osc.js (the npm
// `osc` package, tests/node/vrchat_receiver.js) receives the tracker bundles as VRChat would
// and converts them back to bodyd's space from docs/outputs.md's definitions. Each bundle
// must equal the ZeroMQ pose of the same frame (<= 1 mm, <= 0.1 degree per slot), and its
// head message the head sample as replayed, before the device offset.
// The full VRChat loop: osc.js plays a clip's head and wrists as VRChat sends them
// (tests/drivers/node/send_trackers.js) into bodyd --source vrchat: --output vrchat:.
// Skips (with the reason) when Node.js or the osc package is missing (scripts/setup installs both).
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/tracker_log.h"
#include "bodyd/protocol/pose_message.h"
#include "bodyd/simulators/tracker_sim.h"
#include "../test_paths.h"
#include "zmq_helpers.h"

#include "bodyd/test/net.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <cmath>
#include <cstdlib>

namespace bodyd {
namespace {

namespace fs = std::filesystem;

using test::find_on_path;

using test::read_file;

Vec3 vec(const nlohmann::json& a) { return Vec3(a[0].get<double>(), a[1].get<double>(), a[2].get<double>()); }
Quat quat_xyzw(const nlohmann::json& a) {
  return Quat(a[3].get<double>(), a[0].get<double>(), a[1].get<double>(), a[2].get<double>()).normalized();
}
Vec3 vec(const std::array<float, 3>& a) { return Vec3(a[0], a[1], a[2]); }
Quat quat_xyzw(const std::array<float, 4>& a) { return Quat(a[3], a[0], a[1], a[2]).normalized(); }
double angle_deg(const Quat& a, const Quat& b) { return a.angularDistance(b) * 180.0 / M_PI; }

// osc.js standing in for VRChat's tracker input (tests/node/vrchat_receiver.js).
struct Receiver {
  std::unique_ptr<test::Child> child;
  std::string port;
  fs::path bundles;
};

// Empty `node` with a skip reason when Node.js or the osc package is missing.
std::string node_or_skip_reason(std::string& out_node) {
  out_node = find_on_path("node");
  if (out_node.empty()) return "node (Node.js) is not installed: run scripts/setup";
  if (!fs::exists(test::source_dir() / "tests" / "node" / "node_modules" / "osc" / "package.json"))
    return "the npm package osc is not in tests/node/node_modules: run scripts/setup";
  return {};
}

::testing::AssertionResult start_receiver(const std::string& node, const fs::path& dir, Receiver& r) {
  r.bundles = dir / "bundles.jsonl";
  const fs::path script = test::source_dir() / "tests" / "node" / "vrchat_receiver.js";
  r.child = std::make_unique<test::Child>(
      std::vector<std::string>{node, script.string(), r.bundles.string(), (dir / "port").string(), "1500"}, dir / "node.err");
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (!fs::exists(dir / "port") && r.child->running() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  if (!fs::exists(dir / "port")) return ::testing::AssertionFailure() << "osc.js did not start: " << r.child->log();
  r.port = read_file(dir / "port");
  return ::testing::AssertionSuccess();
}

std::vector<nlohmann::json> read_bundles(const fs::path& file) {
  std::vector<nlohmann::json> bundles;
  std::stringstream lines(read_file(file));
  for (std::string line; std::getline(lines, line);) bundles.push_back(nlohmann::json::parse(line));
  return bundles;
}

using test::collect_until_quiet;

struct Worst {
  double slot_mm = 0, slot_deg = 0, head_mm = 0, head_deg = 0;
  std::size_t matched = 0;
};

const std::pair<const char*, const char*> kSlots[] = {{"1", "Hips"},       {"2", "Foot_L"},     {"3", "Foot_R"},
                                                      {"4", "LowerLeg_L"}, {"5", "LowerLeg_R"}, {"6", "Chest"},
                                                      {"7", "LowerArm_L"}, {"8", "LowerArm_R"}};

// The largest position (mm) and rotation (degrees) difference between bundle b's slots and
// the same joints of `pose`.
std::pair<double, double> slot_error(const nlohmann::json& b, const protocol::PoseMessage& pose,
                                     const std::vector<std::size_t>& joint_of_slot) {
  double mm = 0, deg = 0;
  for (std::size_t k = 0; k < std::size(kSlots); ++k) {
    const nlohmann::json& t = b["trackers"][kSlots[k].first];
    const auto& j = pose.joints[joint_of_slot[k]];
    mm = std::max(mm, (vec(t["p"]) - vec(j.position_m)).norm() * 1000.0);
    deg = std::max(deg, angle_deg(quat_xyzw(t["q"]), quat_xyzw(j.rotation_xyzw)));
  }
  return {mm, deg};
}

// Pairs each bundle with its pose and compares: every slot of a bundle equals the same joint
// of its pose, and its head message equals heads[pose]. Bundles and poses come in the same
// order, one bundle per pose; a bundle the receiver lost (UDP on a loaded machine) is a
// skipped pose: a bundle goes with the first pose after the previous bundle's whose slots
// all match within 1 mm (consecutive poses of a walking clip differ by centimetres).
void compare(const std::vector<protocol::PoseMessage>& poses, const std::vector<nlohmann::json>& bundles,
             const protocol::SkeletonMessage& skeleton, const std::vector<TrackerSample>& heads, Worst& w) {
  ASSERT_EQ(heads.size(), poses.size());
  ASSERT_FALSE(poses.empty());
  std::vector<std::size_t> joint_of_slot;
  for (const auto& [slot, joint] : kSlots) {
    const auto it = std::find(skeleton.names.begin(), skeleton.names.end(), joint);
    ASSERT_NE(it, skeleton.names.end()) << joint;
    joint_of_slot.push_back(static_cast<std::size_t>(it - skeleton.names.begin()));
  }
  std::size_t next = 0;
  for (std::size_t i = 0; i < bundles.size(); ++i) {
    const nlohmann::json& b = bundles[i];
    ASSERT_TRUE(b.value("bundle", false)) << b.dump();
    ASSERT_TRUE(b["bad"].empty()) << b.dump();
    for (const auto& [slot, joint] : kSlots) ASSERT_TRUE(b["trackers"].contains(slot)) << "no tracker " << slot << ": " << b.dump();
    ASSERT_TRUE(b["trackers"].contains("head")) << b.dump();
    std::size_t p = next;
    while (p < poses.size() && slot_error(b, poses[p], joint_of_slot).first > 1.0) ++p;
    ASSERT_LT(p, poses.size()) << "bundle " << i << " matches no pose from " << next << " on (error to that one "
                               << slot_error(b, poses[std::min(next, poses.size() - 1)], joint_of_slot).first << " mm)";
    const auto [mm, deg] = slot_error(b, poses[p], joint_of_slot);
    w.slot_mm = std::max(w.slot_mm, mm);
    w.slot_deg = std::max(w.slot_deg, deg);
    w.head_mm = std::max(w.head_mm, (vec(b["trackers"]["head"]["p"]) - heads[p].position_m).norm() * 1000.0);
    w.head_deg = std::max(w.head_deg, angle_deg(quat_xyzw(b["trackers"]["head"]["q"]), heads[p].rotation));
    ++w.matched;
    next = p + 1;
  }
}

// Every bundle matched to a pose (compare): each slot within 1 mm and 0.1 degree of its joint,
// the head message within 1 mm and 0.1 degree of the head sample; prints the worst.
void expect_bundles_match(const std::vector<protocol::PoseMessage>& poses, const std::vector<nlohmann::json>& bundles,
                          const protocol::SkeletonMessage& skeleton, const std::vector<TrackerSample>& heads) {
  Worst w;
  compare(poses, bundles, skeleton, heads, w);
  EXPECT_LE(w.slot_mm, 1.0);
  EXPECT_LE(w.slot_deg, 0.1);
  EXPECT_LE(w.head_mm, 1.0);
  EXPECT_LE(w.head_deg, 0.1);
  EXPECT_EQ(w.matched, bundles.size());
  std::cout << bundles.size() << " bundles for " << poses.size() << " poses; worst slot " << w.slot_mm << " mm, "
            << w.slot_deg << " deg; head " << w.head_mm << " mm, " << w.head_deg << " deg\n";
}

// Each test: node (or a skip), a temporary directory and the osc.js receiver running in it.
class VrchatOutput : public ::testing::Test {
 protected:
  void SetUp() override {
    if (std::string why = node_or_skip_reason(node); !why.empty()) GTEST_SKIP() << why;
    ASSERT_TRUE(start_receiver(node, dir.path, receiver));
  }
  // bodyd (--method ik) with `args`, its vrchat output sending every slot to osc.js, publishing on
  // TCP with its endpoints in endpoints.json and --control `control`; its log in bodyd.err.
  test::Child start_bodyd(const std::string& control, const std::vector<std::string>& args) const {
    std::vector<std::string> command{(test::bin_dir() / "bodyd").string(), "--method", "ik", "--pub", "tcp://127.0.0.1:*",
                                     "--control", control, "--endpoints-file", (dir.path / "endpoints.json").string(),
                                     "--output", "vrchat:127.0.0.1:" + receiver.port + "?slots=hip,feet,knees,chest,elbows"};
    command.insert(command.end(), args.begin(), args.end());
    return test::Child(command, dir.path / "bodyd.err");
  }
  // The bundled walk, and the arguments that replay it once from the first subscriber on.
  static fs::path walk_log() { return test::source_dir() / "data" / "demo" / "walk.csv"; }
  static std::vector<std::string> replay_walk() {
    return {"--replay", walk_log().string(), "--exit-at-end", "--wait-for-subscriber"};
  }
  std::string node;
  test::TempDir dir;
  Receiver receiver;
};

TEST_F(VrchatOutput, OscJsReceivesTheZmqPoseAndTheHeadAsReceived) {
  // A head offset of 8 cm: the head message must carry the headset's pose before it.
  std::vector<std::string> args = replay_walk();
  args.insert(args.end(), {"--offset", "head=0,-0.08,0.05"});
  test::Child daemon = start_bodyd("none", args);
  zmq::context_t ctx;
  zmq::socket_t sub;
  ASSERT_TRUE(test::subscribe_when_up(ctx, dir.path / "endpoints.json", daemon, sub));
  protocol::SkeletonMessage skeleton;
  std::vector<protocol::PoseMessage> poses;
  collect_until_quiet(sub, skeleton, poses, daemon);  // every pose: the daemon ends with the log
  ASSERT_EQ(daemon.wait(10000), 0) << daemon.log();
  ASSERT_EQ(receiver.child->wait(20000), 0) << receiver.child->log();
  ASSERT_GT(poses.size(), 100u) << daemon.log();
  ASSERT_FALSE(skeleton.names.empty());

  // One bundle per pose, in the same order; a loaded machine may lose a few datagrams.
  const std::vector<nlohmann::json> bundles = read_bundles(receiver.bundles);
  EXPECT_GE(bundles.size() * 100, poses.size() * 95) << bundles.size() << " bundles for " << poses.size() << " poses";
  // One pose per head sample of the log, in order (the replay may move the log's times onto
  // the host clock, so the order is what pairs them).
  std::vector<TrackerSample> heads;
  for (const TrackerSample& h : read_tracker_log(walk_log()).samples)
    if (h.role == Role::Head && h.valid) heads.push_back(h);
  ASSERT_EQ(poses.size(), heads.size()) << daemon.log();
  double offset_min_mm = 1e9;  // how far the offset head (the pose stream's Head) is from the raw one
  for (const TrackerSample& h : heads)
    offset_min_mm = std::min(offset_min_mm, (h.rotation * Vec3(0, -0.08, 0.05)).norm() * 1000.0);
  expect_bundles_match(poses, bundles, skeleton, heads);
  // The head messages matched the raw head samples within 1 mm, which are ~94 mm from the
  // offset ones: the head message is the headset's pose before the device offset.
  EXPECT_GT(offset_min_mm, 50.0);
}

// Issue 45 item 3: `reset` re-centres bodyd's world, not VRChat's. VRChat places the trackers next
// to the head message (the headset as received, in VRChat's space), so after a reset the trackers
// must stay in that space: each bundle's slots are the ZeroMQ pose's joints (the user's re-centred
// space) taken back through the re-centring that `status` reports, and its head message the head
// sample as replayed. (Before, the trackers were sent re-centred next to the head as received.)
TEST_F(VrchatOutput, AfterResetTheTrackersStayInTheSpaceOfVrchatsHead) {
  const std::string control = "ipc://" + (dir.path / "control").string();
  test::Child daemon = start_bodyd(control, replay_walk());
  zmq::context_t ctx;
  zmq::socket_t sub;
  ASSERT_TRUE(test::subscribe_when_up(ctx, dir.path / "endpoints.json", daemon, sub));
  protocol::SkeletonMessage skeleton;
  std::vector<protocol::PoseMessage> poses;
  // Three seconds of the walk, the reset, the rest.
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  test::collect(sub, skeleton, poses, [&] { return std::chrono::steady_clock::now() > until; });
  const std::size_t before = poses.size();
  ASSERT_GT(before, 50u) << daemon.log();
  const auto reset = test::control_request(ctx, control, R"({"cmd":"reset"})");
  ASSERT_TRUE(reset && (*reset)["ok"] == true) << (reset ? reset->dump() : "no reply");
  const auto status = test::control_request(ctx, control, R"({"cmd":"status"})");
  ASSERT_TRUE(status && (*status)["recentred"] == true) << (status ? status->dump() : "");
  // The walk has taken the head well away from where the re-centring puts it.
  ASSERT_GT(test::in_runtime_space({}, 0, *status).origin_m.norm(), 0.5) << status->dump();
  test::collect_until_quiet(sub, skeleton, poses, daemon);
  ASSERT_EQ(daemon.wait(10000), 0) << daemon.log();
  ASSERT_EQ(receiver.child->wait(20000), 0) << receiver.child->log();
  ASSERT_GT(poses.size(), before + 100) << daemon.log();

  std::vector<TrackerSample> log_heads;
  for (const TrackerSample& h : read_tracker_log(walk_log()).samples)
    if (h.role == Role::Head && h.valid) log_heads.push_back(h);
  ASSERT_EQ(poses.size(), log_heads.size()) << daemon.log();
  // The poses in VRChat's space (test::in_runtime_space), each with its head sample.
  const test::RuntimeSpacePoses in_vrchat = test::in_runtime_space(poses, before, *status);
  std::vector<TrackerSample> heads;
  for (std::size_t i : in_vrchat.from) heads.push_back(log_heads[i]);
  const std::vector<nlohmann::json> bundles = read_bundles(receiver.bundles);
  EXPECT_GE(bundles.size() * 100, poses.size() * 95) << bundles.size() << " bundles for " << poses.size() << " poses";
  expect_bundles_match(in_vrchat.poses, bundles, skeleton, heads);
  std::cout << "after the reset (heading " << in_vrchat.heading_rad * 180.0 / M_PI << " deg, origin "
            << in_vrchat.origin_m.x() << ", " << in_vrchat.origin_m.z() << " m)\n";
}

// Issue 9's loop: osc.js plays a clip's head and wrists as VRChat sends them (90 Hz) into
// bodyd --source vrchat: --output vrchat:, and receives the tracker bundles.
TEST_F(VrchatOutput, FullLoopFromVrchatInputToVrchatTrackers) {
  SimOptions sim;  // 90 Hz, the clip's motion without noise or dropouts
  sim.position_noise_mm = 0;
  sim.rotation_noise_deg = 0;
  sim.dropout_rate_hz = 0;
  const std::vector<TrackerSample> samples = simulate_trackers(read_bvh(test::fixtures() / "walk_60.bvh"), sim);
  write_tracker_log(dir.path / "walk.csv", samples);
  std::vector<TrackerSample> heads;
  for (const TrackerSample& s : samples)
    if (s.role == Role::Head && s.valid) heads.push_back(s);

  const std::string in_port = std::to_string(test::free_loopback_port());
  test::Child daemon = start_bodyd("none", {"--source", "vrchat:127.0.0.1:" + in_port + "?oscquery=off"});
  zmq::context_t ctx;
  zmq::socket_t sub;
  ASSERT_TRUE(test::subscribe_when_up(ctx, dir.path / "endpoints.json", daemon, sub));

  ::setenv("NODE_PATH", (test::source_dir() / "tests" / "node" / "node_modules").c_str(), 1);  // for send_trackers.js
  test::Child sender({node, (test::source_dir() / "tests" / "drivers" / "node" / "send_trackers.js").string(), "vrchat",
                      "127.0.0.1", in_port, (dir.path / "walk.csv").string(), "11"},
                     dir.path / "sender.err");
  protocol::SkeletonMessage skeleton;
  std::vector<protocol::PoseMessage> poses;
  collect_until_quiet(sub, skeleton, poses, sender);
  ASSERT_EQ(sender.wait(0), 0) << sender.log();
  daemon.signal(SIGINT);
  ASSERT_EQ(daemon.wait(10000), 0) << daemon.log();
  ASSERT_EQ(receiver.child->wait(20000), 0) << receiver.child->log();
  ASSERT_FALSE(skeleton.names.empty()) << "no skeleton message (bodyd sends it to each new subscriber)";
  // One pose per head sample sent (the poses are matched to the sent heads by order), one
  // bundle per pose; a loaded machine may lose a few datagrams on the way out.
  ASSERT_EQ(poses.size(), heads.size()) << daemon.log();
  const std::vector<nlohmann::json> bundles = read_bundles(receiver.bundles);
  EXPECT_GE(bundles.size() * 100, poses.size() * 95) << bundles.size() << " bundles for " << poses.size() << " poses";
  // The head alignment message equals what "VRChat" sent (through Unity Euler angles in
  // float, both ways).
  expect_bundles_match(poses, bundles, skeleton, heads);
}

}  // namespace
}  // namespace bodyd
