// End to end over real sockets: the C++ client, the C ABI from C, the Python example, bodyd-sub
// and bodyd-record against an in-process publisher on tcp://127.0.0.1:* and ipc://.
#include "bodyd/client/client.h"
#include "bodyd_client.h"
#include "bodyd/protocol/recording.h"
#include "bodyd/protocol/synthetic.h"
#include "bodyd/test/pose_message.h"
#include "../test_paths.h"
#include "test_publisher.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>
#include <sstream>

namespace bodyd::test {
namespace {

using ::testing::HasSubstr;
using namespace std::chrono_literals;
using protocol::PoseMessage;
using protocol::synthetic_pose;
using protocol::synthetic_skeleton;

constexpr const char* kPython = "/usr/bin/python3";
using F3 = std::array<float, 3>;
using F4 = std::array<float, 4>;

std::unique_ptr<client::Client> connect(const std::string& pose, const std::string& control = "") {
  client::ClientOptions options;
  options.pose_endpoint = pose;
  options.control_endpoint = control;
  std::string error;
  auto c = client::Client::connect(options, error);
  EXPECT_NE(c, nullptr) << error;
  return c;
}

// Receives until a pose arrives (or 5 s pass).
client::Received receive_pose(client::Client& c, PoseMessage& out) {
  client::Received r = client::Received::kTimeout;
  for (int i = 0; i < 50 && r == client::Received::kTimeout; ++i) r = c.receive(out, 100ms);
  return r;
}

// A received pose is the synthetic pose of its seq, field by field and bit for bit.
void expect_synthetic(const PoseMessage& p) { EXPECT_TRUE(test::same_pose(p, synthetic_pose(p.seq))); }

// A subscriber's JSON line k: its seq is newer than the line before's (`last`), and its times
// and flags are those of the synthetic pose of that seq, which is returned.
template <class Json>
PoseMessage expect_synthetic_line(const Json& j, std::size_t k, std::uint64_t& last) {
  const std::uint64_t seq = j["seq"];
  if (k > 0) {
    EXPECT_GT(seq, last);
  }
  last = seq;
  const PoseMessage e = synthetic_pose(seq);
  EXPECT_EQ(j["t_ns"].template get<std::int64_t>(), e.t_ns);
  EXPECT_EQ(j["publish_t_ns"].template get<std::int64_t>(), e.publish_t_ns);
  EXPECT_EQ(j["flags"].template get<std::uint32_t>(), e.flags);
  return e;
}

std::string quoted(const std::string& s) { return "'" + s + "'"; }

// ---- C++ client ------------------------------------------------------------------------------

TEST(ClientCpp, TimeoutIsAValueAndPosesArriveTyped) {
  TestPublisher pub;
  auto c = connect(pub.endpoint());
  PoseMessage pose;
  // Nothing can have arrived yet: the publisher waits for our subscription, which takes time.
  EXPECT_EQ(c->receive(pose, 0ms), client::Received::kTimeout);
  ASSERT_EQ(receive_pose(*c, pose), client::Received::kPose) << c->error();
  std::uint64_t last = pose.seq;
  expect_synthetic(pose);
  for (int i = 0; i < 30; ++i) {
    ASSERT_EQ(receive_pose(*c, pose), client::Received::kPose) << c->error();
    EXPECT_GT(pose.seq, last);
    last = pose.seq;
    expect_synthetic(pose);
  }
  EXPECT_EQ(c->stats().poses, 31u);
  EXPECT_EQ(c->stats().malformed, 0u);
  EXPECT_EQ(c->stats().restarts, 0u);
  // The skeleton arrives on the stream (every 20 ms from this publisher).
  ASSERT_TRUE(c->current_skeleton().has_value());
  EXPECT_EQ(c->current_skeleton()->names, synthetic_skeleton().names);
}

TEST(ClientCpp, SeqGapsAreCountedAsDropped) {
  TestPublisher::Options o;
  o.before_poses = [](zmq::socket_t& s) {
    std::vector<std::uint8_t> b;
    for (std::uint64_t seq : {100u, 101u, 105u}) {  // 3 missing between 101 and 105
      (void)protocol::encode_pose(synthetic_pose(seq), b);
      s.send(zmq::buffer(protocol::kPoseTopic), zmq::send_flags::sndmore);
      s.send(zmq::buffer(b), zmq::send_flags::none);
    }
  };
  o.max_poses = 0;
  TestPublisher pub(o);
  auto c = connect(pub.endpoint());
  PoseMessage pose;
  for (std::uint64_t expected : {100u, 101u, 105u}) {
    ASSERT_EQ(receive_pose(*c, pose), client::Received::kPose);
    EXPECT_EQ(pose.seq, expected);
  }
  EXPECT_EQ(c->stats().dropped, 3u);
}

TEST(ClientCpp, MalformedMessagesAreReportedAndSkipped) {
  TestPublisher::Options o;
  o.send_skeleton = false;
  o.before_poses = [](zmq::socket_t& s) {
    const std::string junk = "not a pose";
    s.send(zmq::buffer(protocol::kPoseTopic), zmq::send_flags::sndmore);
    s.send(zmq::buffer(junk), zmq::send_flags::none);
    s.send(zmq::buffer(protocol::kPoseTopic), zmq::send_flags::none);  // one frame only
    std::vector<std::uint8_t> b;
    (void)protocol::encode_pose(synthetic_pose(7), b);
    b[4] = 9;  // version 9
    s.send(zmq::buffer(protocol::kPoseTopic), zmq::send_flags::sndmore);
    s.send(zmq::buffer(b), zmq::send_flags::none);
  };
  TestPublisher pub(o);
  auto c = connect(pub.endpoint());
  PoseMessage pose;
  std::vector<std::string> errors;
  client::Received r;
  while ((r = receive_pose(*c, pose)) == client::Received::kMalformed) errors.push_back(c->error());
  ASSERT_EQ(r, client::Received::kPose);
  EXPECT_EQ(pose.seq, 0u);
  ASSERT_EQ(errors.size(), 3u);
  EXPECT_THAT(errors[0], HasSubstr("shorter than the 64-byte header"));
  EXPECT_THAT(errors[1], HasSubstr("1 frames"));
  EXPECT_THAT(errors[2], HasSubstr("unsupported version 9"));
  EXPECT_EQ(c->stats().malformed, 3u);
}

TEST(ClientCpp, SurvivesAPublisherRestart) {
  const std::string endpoint = ipc_endpoint("pose");
  TestPublisher::Options o;
  o.endpoint = endpoint;
  auto first = std::make_unique<TestPublisher>(o);
  auto c = connect(endpoint);
  PoseMessage pose;
  ASSERT_EQ(receive_pose(*c, pose), client::Received::kPose);
  // Let it run ahead so the restarted stream's seq is lower.
  while (first->poses_sent() < pose.seq + 50) std::this_thread::sleep_for(5ms);
  while (c->receive(pose, 0ms) == client::Received::kPose) {
  }
  const std::uint64_t before = pose.seq;
  ASSERT_GT(before, 20u);
  first.reset();  // the daemon stops...
  TestPublisher second(o);  // ...and starts again on the same endpoint, seq from 0
  bool restarted = false;
  for (int i = 0; i < 100 && !restarted; ++i) {
    ASSERT_EQ(receive_pose(*c, pose), client::Received::kPose) << c->error();
    restarted = pose.seq < before;
  }
  EXPECT_TRUE(restarted);
  EXPECT_GE(c->stats().restarts, 1u);
  expect_synthetic(pose);
}

TEST(ClientCpp, ControlRequests) {
  TestControlServer control;
  TestPublisher pub;
  auto c = connect(pub.endpoint(), control.endpoint());
  protocol::SkeletonMessage s;
  ASSERT_TRUE(c->skeleton(s).ok());
  EXPECT_EQ(s.names, synthetic_skeleton().names);
  EXPECT_EQ(s.offsets_m, synthetic_skeleton().offsets_m);
  EXPECT_EQ(s.skeleton_id, synthetic_skeleton().skeleton_id);
  ASSERT_TRUE(c->current_skeleton().has_value());
  const auto reply = c->request({{"cmd", "frobnicate"}});
  EXPECT_FALSE(reply.ok);
  EXPECT_EQ(reply.error, "unknown command");
}

TEST(ClientCpp, ControlTimeoutIsReportedAndTheNextRequestWorks) {
  // Nothing listens yet at the control endpoint.
  const std::string endpoint = ipc_endpoint("control");
  TestPublisher pub;
  auto c = connect(pub.endpoint(), endpoint);
  auto reply = c->request({{"cmd", "skeleton"}}, 100ms);
  EXPECT_FALSE(reply.ok);
  EXPECT_THAT(reply.error, HasSubstr("no reply from control endpoint"));
  TestControlServer control(endpoint);
  protocol::SkeletonMessage s;
  const protocol::Status st = c->skeleton(s, 5000ms);
  EXPECT_TRUE(st.ok()) << st.error;
}

// bodyd-ctl's use (issue 45 item 4): a control client without a pose stream, which tells a
// timeout (no daemon) from an answer.
TEST(ClientCpp, AControlOnlyClientTellsATimeoutFromAnAnswer) {
  const std::string endpoint = ipc_endpoint("control-only");
  auto c = connect("", endpoint);
  ASSERT_NE(c, nullptr);
  PoseMessage pose;
  EXPECT_EQ(c->receive(pose, 0ms), client::Received::kError);
  EXPECT_EQ(c->error(), "no pose endpoint configured");
  auto reply = c->request({{"cmd", "status"}}, 100ms);
  EXPECT_FALSE(reply.ok);
  EXPECT_TRUE(reply.timed_out);
  TestControlServer control(endpoint);
  reply = c->request({{"cmd", "frobnicate"}}, 5000ms);
  EXPECT_FALSE(reply.timed_out) << reply.error;
  EXPECT_FALSE(reply.ok);
  EXPECT_EQ(reply.error, "unknown command");
}

TEST(ClientCpp, SkeletonJsonIsChecked) {
  auto j = client::skeleton_to_json(synthetic_skeleton());
  protocol::SkeletonMessage s;
  ASSERT_TRUE(client::skeleton_from_json(j, s).ok());
  auto bad = j;
  bad["skeleton_id"] = 1;
  EXPECT_THAT(client::skeleton_from_json(bad, s).error, HasSubstr("does not match the skeleton's hash"));
  bad = j;
  bad["parents"][3] = 7;
  EXPECT_THAT(client::skeleton_from_json(bad, s).error, HasSubstr("joint 3"));
  bad = j;
  bad["offsets_m"][2] = {1, 2};
  EXPECT_THAT(client::skeleton_from_json(bad, s).error, HasSubstr("offsets_m[2]"));
  bad = j;
  bad.erase("names");
  EXPECT_THAT(client::skeleton_from_json(bad, s).error, HasSubstr("missing field \"names\""));
}

// A version-2 skeleton (rest rotations) through the control reply's JSON: the same id.
TEST(ClientCpp, SkeletonJsonCarriesRestRotations) {
  protocol::SkeletonMessage sk = synthetic_skeleton();
  for (std::size_t i = 0; i < sk.names.size(); ++i)
    sk.rest_rotations_xyzw.push_back({0.0f, 0.6f, 0.0f, i % 2 ? 0.8f : -0.8f});
  sk.skeleton_id = protocol::skeleton_id_of(sk);
  const auto j = client::skeleton_to_json(sk);
  ASSERT_TRUE(j.contains("rest_rotations_xyzw"));
  protocol::SkeletonMessage s;
  ASSERT_TRUE(client::skeleton_from_json(j, s).ok()) << client::skeleton_from_json(j, s).error;
  EXPECT_EQ(s.rest_rotations_xyzw, sk.rest_rotations_xyzw);
  EXPECT_EQ(s.skeleton_id, sk.skeleton_id);
  auto bad = j;
  bad["rest_rotations_xyzw"][1] = {0, 0, 1};
  EXPECT_THAT(client::skeleton_from_json(bad, s).error, HasSubstr("rest_rotations_xyzw[1]"));
  bad = j;
  bad["rest_rotations_xyzw"][1] = {0, 0, 2, 0};
  EXPECT_THAT(client::skeleton_from_json(bad, s).error, HasSubstr("rest rotation has norm 2"));
  bad = j;
  bad.erase("rest_rotations_xyzw");  // the id covers the rest rotations
  EXPECT_THAT(client::skeleton_from_json(bad, s).error, HasSubstr("does not match the skeleton's hash"));
}

TEST(ClientCpp, InvalidEndpointIsAnError) {
  client::ClientOptions o;
  o.pose_endpoint = "tcp://";
  std::string error;
  EXPECT_EQ(client::Client::connect(o, error), nullptr);
  EXPECT_THAT(error, HasSubstr("pose endpoint \"tcp://\""));
}

// ---- C ABI from C ------------------------------------------------------------------------

// Issue 20 item 9: the C ABI gives the skeleton's rest rotations (a P/Invoke client with no
// JSON parser needs them to retarget), and says when a skeleton has none.
TEST(ClientCApi, RestRotationsOfTheSkeleton) {
  protocol::SkeletonMessage v2 = synthetic_skeleton();
  for (std::size_t i = 0; i < v2.names.size(); ++i) {
    const float a = 0.05f * static_cast<float>(i);
    v2.rest_rotations_xyzw.push_back({std::sin(a), 0.0f, 0.0f, std::cos(a)});
  }
  v2.skeleton_id = protocol::skeleton_id_of(v2);
  TestControlServer with_rest("tcp://127.0.0.1:*", v2);
  bodyd_client* c = bodyd_client_create("tcp://127.0.0.1:9", with_rest.endpoint().c_str());
  ASSERT_NE(c, nullptr) << bodyd_client_error(nullptr);
  float q[4] = {0, 0, 0, 0};
  EXPECT_EQ(bodyd_client_skeleton_rest_rotation(c, 0, q), BODYD_ERROR_NO_SKELETON);
  ASSERT_EQ(bodyd_client_fetch_skeleton(c, 5000), BODYD_OK) << bodyd_client_error(c);
  ASSERT_EQ(bodyd_client_skeleton_id(c), v2.skeleton_id);
  for (std::uint32_t i = 0; i < v2.names.size(); ++i) {
    ASSERT_EQ(bodyd_client_skeleton_rest_rotation(c, i, q), BODYD_OK) << i;
    EXPECT_EQ((F4{q[0], q[1], q[2], q[3]}), v2.rest_rotations_xyzw[i]) << i;
  }
  EXPECT_EQ(bodyd_client_skeleton_rest_rotation(c, 22, q), BODYD_ERROR_ARGUMENT);
  EXPECT_EQ(bodyd_client_skeleton_rest_rotation(c, 1, nullptr), BODYD_ERROR_ARGUMENT);
  EXPECT_EQ(bodyd_client_skeleton_rest_rotation(nullptr, 1, q), BODYD_ERROR_ARGUMENT);
  bodyd_client_destroy(c);

  TestControlServer without_rest;  // the synthetic skeleton is a version-1 one
  c = bodyd_client_create("tcp://127.0.0.1:9", without_rest.endpoint().c_str());
  ASSERT_NE(c, nullptr);
  ASSERT_EQ(bodyd_client_fetch_skeleton(c, 5000), BODYD_OK) << bodyd_client_error(c);
  EXPECT_EQ(bodyd_client_skeleton_rest_rotation(c, 1, q), BODYD_ERROR_NO_REST_POSE);
  bodyd_client_destroy(c);
}

TEST(ClientCApi, UsedFromC) {
  TestControlServer control;
  TestPublisher pub;
  const auto r = shell(fmt::format("timeout 60 {} {} {} 25", BODYD_CLIENT_C_TEST, quoted(pub.endpoint()),
                                         quoted(control.endpoint())));
  ASSERT_EQ(r.status, 0) << r.out;
  int poses = 0;
  for (const std::string& line : lines_of(r.out)) {
    std::istringstream in(line);
    std::string tag;
    std::uint64_t seq;
    unsigned joint_count, root_joint, flags, foot, skeleton_id;
    long long t_ns;
    std::array<float, 3> p;
    std::array<float, 4> q;
    in >> tag >> seq >> joint_count >> root_joint >> flags >> foot >> skeleton_id >> t_ns >> p[0] >> p[1] >> p[2] >>
        q[0] >> q[1] >> q[2] >> q[3];
    ASSERT_TRUE(in && tag == "POSE") << line;
    const PoseMessage e = synthetic_pose(seq);
    EXPECT_EQ(joint_count, e.joints.size());
    EXPECT_EQ(flags, e.flags);
    EXPECT_EQ(foot, e.foot_contact);
    EXPECT_EQ(skeleton_id, e.skeleton_id);
    EXPECT_EQ(t_ns, e.t_ns);
    EXPECT_EQ(p, e.joints[5].position_m);
    EXPECT_EQ(q, e.joints[5].rotation_xyzw);
    ++poses;
  }
  EXPECT_EQ(poses, 25);
}

// ---- Python example, from docs/protocol.md alone --------------------------------------------

TEST(PythonSubscriber, DecodesEveryField) {
  TestPublisher pub;
  const std::string script = (source_dir() / "examples/python/bodyd_sub.py").string();
  const auto r = shell(fmt::format("timeout 60 {} {} --endpoint {} --count 40 --json --timeout-s 20", kPython,
                                         script, quoted(pub.endpoint())));
  ASSERT_EQ(r.status, 0) << "is python3-zmq installed (scripts/setup)?\n" << r.out;
  const auto lines = lines_of(r.out);
  ASSERT_EQ(lines.size(), 40u);
  std::uint64_t last = 0;
  bool named = false;
  for (std::size_t k = 0; k < lines.size(); ++k) {
    const auto j = nlohmann::json::parse(lines[k]);
    const PoseMessage e = expect_synthetic_line(j, k, last);
    const std::uint64_t seq = e.seq;
    EXPECT_EQ(j["skeleton_id"].get<std::uint32_t>(), e.skeleton_id);
    EXPECT_EQ(j["root_joint"].get<int>(), 1);
    EXPECT_EQ(j["foot_contact"][0].get<bool>(), (e.foot_contact & 1) != 0);
    EXPECT_EQ(j["foot_contact"][1].get<bool>(), (e.foot_contact & 2) != 0);
    EXPECT_EQ(j["root_position_m"].get<F3>(), e.root_position_m);
    EXPECT_EQ(j["root_heading_rad"].get<float>(), e.root_heading_rad);
    ASSERT_EQ(j["positions_m"].size(), 22u);
    for (std::size_t i = 0; i < 22; ++i) {
      EXPECT_EQ(j["positions_m"][i].get<F3>(), e.joints[i].position_m) << seq << " " << i;
      EXPECT_EQ(j["rotations_xyzw"][i].get<F4>(), e.joints[i].rotation_xyzw) << seq << " " << i;
    }
    if (j.contains("joints")) {  // names, once the skeleton message has been decoded
      named = true;
      EXPECT_EQ(j["joints"]["Toes_R"].get<F3>(), e.joints[21].position_m);
    }
  }
  EXPECT_TRUE(named) << "the Python subscriber never decoded a skeleton message";
}

// ---- bodyd-sub -----------------------------------------------------------------------------

void check_bodyd_sub_json(const std::string& endpoint) {
  const auto r = shell(fmt::format("timeout 60 {} --endpoint {} --count 30 --json --rotations --wait-skeleton "
                                         "--timeout-s 20", BODYD_SUB, quoted(endpoint)));
  ASSERT_EQ(r.status, 0) << r.out;
  const auto lines = lines_of(r.out);
  ASSERT_EQ(lines.size(), 30u);
  std::uint64_t last = 0;
  const auto names = synthetic_skeleton().names;
  for (std::size_t k = 0; k < lines.size(); ++k) {
    const auto j = nlohmann::ordered_json::parse(lines[k]);
    EXPECT_EQ(j.begin().key(), "seq");
    const PoseMessage e = expect_synthetic_line(j, k, last);
    ASSERT_TRUE(j["joints"].is_object()) << lines[k];
    for (std::size_t i = 0; i < names.size(); ++i) {
      EXPECT_EQ(j["joints"][names[i]].get<F3>(), e.joints[i].position_m);
      EXPECT_EQ(j["rotations_xyzw"][names[i]].get<F4>(), e.joints[i].rotation_xyzw);
    }
  }
}

TEST(BodydSub, JsonOverTcp) {
  TestPublisher pub;
  check_bodyd_sub_json(pub.endpoint());
}

TEST(BodydSub, JsonOverIpc) {
  TestPublisher::Options o;
  o.endpoint = ipc_endpoint("pose");
  TestPublisher pub(o);
  check_bodyd_sub_json(pub.endpoint());
}

TEST(BodydSub, SummaryLine) {
  TestPublisher pub;
  const auto r = shell(fmt::format("timeout 60 {} --endpoint {} --count 50 --timeout-s 20 2>&1", BODYD_SUB,
                                         quoted(pub.endpoint())));
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_THAT(r.out, HasSubstr(" Hz | publish-sample p50 "));
  EXPECT_THAT(r.out, HasSubstr("bodyd-sub: 50 poses"));
}

TEST(BodydSub, NoPublisherTimesOutWithStatus2) {
  const auto r = shell(fmt::format("timeout 60 {} --endpoint {} --timeout-s 0.3 2>&1", BODYD_SUB,
                                         quoted(ipc_endpoint("nobody"))));
  EXPECT_EQ(r.status, 2) << r.out;
  EXPECT_THAT(r.out, HasSubstr("no pose from"));
}

// ---- bodyd-record ------------------------------------------------------------------------------

TEST(BodydRecord, RecordsAndLoadsBack) {
  TestPublisher pub;
  const auto path = std::filesystem::temp_directory_path() / fmt::format("bodyd-record-{}.bdrec", ::getpid());
  const auto r = shell(fmt::format("timeout 60 {} --endpoint {} --out {} --count 60 --timeout-s 20 2>&1",
                                         BODYD_RECORD, quoted(pub.endpoint()), quoted(path.string())));
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_THAT(r.out, HasSubstr("bodyd-record: 60 poses"));
  protocol::PoseRecording rec;
  const protocol::Status s = protocol::load_pose_recording(path, rec);
  ASSERT_TRUE(s.ok()) << s.error;
  ASSERT_EQ(rec.poses.size(), 60u);
  ASSERT_GE(rec.skeletons.size(), 1u);
  EXPECT_EQ(rec.skeletons[0].names, synthetic_skeleton().names);
  for (std::size_t k = 0; k < rec.poses.size(); ++k) {
    if (k > 0) {
      EXPECT_GT(rec.poses[k].seq, rec.poses[k - 1].seq);
      EXPECT_GE(rec.pose_recv_t_ns[k], rec.pose_recv_t_ns[k - 1]);
    }
    expect_synthetic(rec.poses[k]);
    EXPECT_NE(protocol::find_skeleton(rec, rec.poses[k].skeleton_id), nullptr);
  }
  std::filesystem::remove(path);
}

TEST(BodydRecord, DurationLimitWithoutPublisher) {
  const auto path = std::filesystem::temp_directory_path() / fmt::format("bodyd-record-empty-{}.bdrec", ::getpid());
  const auto r = shell(fmt::format("timeout 60 {} --endpoint {} --out {} --duration-s 0.3 2>&1", BODYD_RECORD,
                                         quoted(ipc_endpoint("nobody")), quoted(path.string())));
  ASSERT_EQ(r.status, 0) << r.out;
  protocol::PoseRecording rec;
  ASSERT_TRUE(protocol::load_pose_recording(path, rec).ok());
  EXPECT_TRUE(rec.poses.empty());
  EXPECT_GT(rec.created_unix_ns, 0);
  std::filesystem::remove(path);
}

TEST(BodydRecord, UnwritableOutputIsAnError) {
  const auto r = shell(fmt::format("timeout 60 {} --endpoint {} --out /nonexistent-dir/x.bdrec 2>&1",
                                         BODYD_RECORD, quoted(ipc_endpoint("nobody"))));
  EXPECT_EQ(r.status, 1);
  EXPECT_THAT(r.out, HasSubstr("cannot create /nonexistent-dir/x.bdrec"));
}

}  // namespace
}  // namespace bodyd::test
