// Unit tests of the daemon's parts: the sample queue, endpoint rules, CURVE key files, the
// config file and flags, the control request parser, and the replay/sim sources.
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/control.h"
#include "bodyd/io/zmq/endpoint.h"
#include "bodyd/daemon/sample_queue.h"
#include "bodyd/io/open_source.h"
#include "bodyd/io/replay/replay_source.h"
#include "bodyd/motion/limits.h"
#include "bodyd/motion/tracker_log.h"
#include "fake_reconstructor.h"
#include "../test_paths.h"
#include "zmq_helpers.h"

#include "bodyd/test/wait.h"

#include <gtest/gtest.h>

#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>

#include <cstring>
#include <fstream>
#include <thread>

namespace bodyd {
namespace {

using daemon::SampleQueue;
using drivers::SourceSample;
using namespace std::chrono_literals;

SourceSample sample_at(std::int64_t t_ns, Role role = Role::Head) {
  SourceSample s;
  s.sample.t_ns = t_ns;
  s.sample.role = role;
  s.sample.valid = true;
  return s;
}

// ------------------------------------------------------------------------ SampleQueue

TEST(SampleQueue, KeepsOrderAndDropsOldestWhenFull) {
  SampleQueue q(4);
  for (int i = 0; i < 6; ++i) q.push(sample_at(i));
  EXPECT_EQ(q.size(), 4u);
  EXPECT_EQ(q.dropped(), 2u);
  EXPECT_EQ(q.pushed(), 6u);
  SourceSample out;
  for (int i = 2; i < 6; ++i) {
    ASSERT_TRUE(q.pop(out, 0ms));
    EXPECT_EQ(out.sample.t_ns, i);  // 0 and 1 were dropped: the newest survive
  }
  EXPECT_FALSE(q.pop(out, 1ms));
}

// Issue 11: under overload the queue filled with seconds of old samples and every pose came
// that late. With a max age, pop skips (and counts) what arrived more than max_age before the
// newest queued sample. The arrival stamps are set here: no clock, no timing.
SourceSample arrived_at(std::int64_t arrival_ms, Role role = Role::Head) {
  SourceSample s = sample_at(arrival_ms * 1'000'000, role);
  s.arrival_ns = arrival_ms * 1'000'000;
  return s;
}

TEST(SampleQueue, DropsSamplesMoreThanMaxAgeBehindTheNewest) {
  SampleQueue q(1024, 100ms);
  // A consumer that fell behind: 11 ms apart, 300 samples = 3.3 s queued.
  for (int i = 0; i < 300; ++i) q.push(arrived_at(11 * i, static_cast<Role>(i % 3)));
  EXPECT_EQ(q.size(), 300u);
  SourceSample out;
  ASSERT_TRUE(q.pop(out, 0ms));
  // Newest arrived at 3289 ms: everything before 3189 ms is stale; the first kept is 3190 ms.
  EXPECT_EQ(out.arrival_ns, 3190'000'000);
  EXPECT_EQ(q.dropped_stale(), 290u);
  EXPECT_EQ(q.dropped(), 0u);
  // The rest come in order, none dropped (all within 100 ms of the newest).
  for (int i = 291; i < 300; ++i) {
    ASSERT_TRUE(q.pop(out, 0ms));
    EXPECT_EQ(out.arrival_ns, 11'000'000LL * i);
  }
  EXPECT_EQ(q.dropped_stale(), 290u);
  // Exactly max_age behind is not stale; a lone sample is never dropped, however old.
  q.push(arrived_at(10'000));
  q.push(arrived_at(10'100));
  ASSERT_TRUE(q.pop(out, 0ms));
  EXPECT_EQ(out.arrival_ns, 10'000'000'000);
  ASSERT_TRUE(q.pop(out, 0ms));
  q.push(arrived_at(0));
  ASSERT_TRUE(q.pop(out, 0ms));
  EXPECT_EQ(out.arrival_ns, 0);
  EXPECT_EQ(q.dropped_stale(), 290u);
}

TEST(SampleQueue, WithoutMaxAgeOrWithPushWaitNothingIsDroppedForAge) {
  SampleQueue plain(1024);
  for (int i = 0; i < 300; ++i) plain.push(arrived_at(11 * i));
  SourceSample out;
  ASSERT_TRUE(plain.pop(out, 0ms));
  EXPECT_EQ(out.arrival_ns, 0);  // the old behaviour: the oldest first
  EXPECT_EQ(plain.dropped_stale(), 0u);

  // A lossless replay (push_wait) loses nothing to age, even mixed with a live source's samples.
  SampleQueue q(1024, 100ms);
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(q.push_wait(arrived_at(11 * i), 0ms));
  q.push(arrived_at(5000));
  for (int i = 0; i < 100; ++i) {
    ASSERT_TRUE(q.pop(out, 0ms));
    EXPECT_EQ(out.arrival_ns, 11'000'000LL * i);
  }
  ASSERT_TRUE(q.pop(out, 0ms));
  EXPECT_EQ(out.arrival_ns, 5'000'000'000);
  EXPECT_EQ(q.dropped_stale(), 0u);
}

TEST(SampleQueueDeathTest, NoCapacityOrANegativeAgeIsABug) {
  // The Daemon clamps the configured queue_capacity and queue_max_age_ms: only bodyd's code can pass these.
  EXPECT_DEATH(SampleQueue(4, -1ms), "bug: SampleQueue: max_age must be >= 0");
  EXPECT_DEATH(SampleQueue(0), "bug: SampleQueue: capacity must be > 0");
}

TEST(SampleQueue, PushWaitTimesOutWhenFullAndSucceedsWhenDrained) {
  SampleQueue q(2);
  ASSERT_TRUE(q.push_wait(sample_at(1), 0ms));
  ASSERT_TRUE(q.push_wait(sample_at(2), 0ms));
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(q.push_wait(sample_at(3), 30ms));
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 25ms);
  EXPECT_EQ(q.dropped(), 0u);
  std::thread consumer([&] {
    std::this_thread::sleep_for(20ms);
    SourceSample out;
    (void)q.pop(out, 100ms);
  });
  EXPECT_TRUE(q.push_wait(sample_at(3), 2s));
  consumer.join();
  SourceSample out;
  ASSERT_TRUE(q.pop(out, 0ms));
  EXPECT_EQ(out.sample.t_ns, 2);
  ASSERT_TRUE(q.pop(out, 0ms));
  EXPECT_EQ(out.sample.t_ns, 3);
}

TEST(SampleQueue, ManyProducersOneConsumerLoseNothingWithPushWait) {
  SampleQueue q(16);
  constexpr int kPerProducer = 2000;
  std::vector<std::thread> producers;
  for (int p = 0; p < 3; ++p)
    producers.emplace_back([&, p] {
      for (int i = 0; i < kPerProducer; ++i) {
        SourceSample s = sample_at(i, static_cast<Role>(p));
        while (!q.push_wait(s, 10ms)) {
        }
      }
    });
  std::array<std::int64_t, 3> next{};
  int received = 0;
  SourceSample out;
  while (received < 3 * kPerProducer) {
    ASSERT_TRUE(q.pop(out, 2s));
    const int r = static_cast<int>(out.sample.role);
    ASSERT_EQ(out.sample.t_ns, next[r]) << "role " << r;  // per producer, in order
    ++next[r];
    ++received;
  }
  for (auto& t : producers) t.join();
  EXPECT_EQ(q.dropped(), 0u);
}

// ------------------------------------------------------------------------ endpoints

TEST(Endpoint, LocalOnlyByDefault) {
  for (const char* ok : {"ipc:///tmp/bodyd/pose", "inproc://x", "tcp://127.0.0.1:5555", "tcp://127.0.0.1:*",
                         "tcp://127.3.2.1:0", "tcp://localhost:5555", "tcp://[::1]:5555", "tcp://lo:5555"}) {
    EXPECT_TRUE(daemon::is_local_endpoint(ok)) << ok;
    EXPECT_EQ(daemon::check_bind_endpoint(ok, false, "--pub"), "") << ok;
  }
  for (const char* remote : {"tcp://0.0.0.0:5555", "tcp://*:5555", "tcp://192.168.1.10:5555", "tcp://eth0:5555",
                             "tcp://[::]:5555", "tcp://128.0.0.1:1", "pgm://eth0;239.192.1.1:5555",
                             "ws://127.0.0.1:80"}) {
    EXPECT_FALSE(daemon::is_local_endpoint(remote)) << remote;
    const std::string e = daemon::check_bind_endpoint(remote, false, "--pub");
    EXPECT_NE(e.find("--allow-remote"), std::string::npos) << remote << ": " << e;
    EXPECT_NE(e.find(remote), std::string::npos) << e;
    EXPECT_EQ(daemon::check_bind_endpoint(remote, true, "--pub"), "") << remote;
  }
  EXPECT_NE(daemon::check_bind_endpoint("", false, "--pub"), "");
  EXPECT_NE(daemon::check_bind_endpoint("127.0.0.1:5555", false, "--pub").find("not a ZeroMQ endpoint"), std::string::npos);
  EXPECT_NE(daemon::check_bind_endpoint("tcp://127.0.0.1", false, "--pub").find("tcp://HOST:PORT"), std::string::npos);
}

TEST(Endpoint, IpcDirectoryIsCreatedPrivateAndALiveSocketIsRefused) {
  test::TempDir dir;
  const auto path = dir.path / "sub" / "pose";
  const std::string endpoint = "ipc://" + path.string();
  ASSERT_EQ(daemon::prepare_ipc_endpoint(endpoint, "--pub"), "");
  struct stat st {};
  ASSERT_EQ(::stat((dir.path / "sub").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0700u);

  // A stale socket file (nobody listening) is fine; a live one is "in use".
  zmq::context_t ctx;
  {
    zmq::socket_t s(ctx, zmq::socket_type::pub);
    s.set(zmq::sockopt::linger, 0);
    s.bind(endpoint);
    const std::string e = daemon::prepare_ipc_endpoint(endpoint, "--pub");
    EXPECT_NE(e.find("another bodyd running?"), std::string::npos) << e;
  }
  // After close, ZeroMQ removes the file; a leftover file from a crash is simulated by hand.
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  std::filesystem::remove(path);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);  // bound, not listening
  ::close(fd);
  ASSERT_TRUE(std::filesystem::exists(path));
  EXPECT_EQ(daemon::prepare_ipc_endpoint(endpoint, "--pub"), "");
}

TEST(Curve, GeneratedKeysReadBackAndSecretIsPrivate) {
  test::TempDir dir;
  daemon::CurveKeyPair keys;
  ASSERT_EQ(daemon::generate_curve_keys(dir.path / "keys", keys), "");
  std::string pub, sec;
  ASSERT_EQ(daemon::read_curve_key_file(dir.path / "keys" / "server.public", pub), "");
  ASSERT_EQ(daemon::read_curve_key_file(dir.path / "keys" / "server.secret", sec), "");
  EXPECT_EQ(pub, keys.public_key);
  EXPECT_EQ(sec, keys.secret_key);
  EXPECT_EQ(daemon::curve_public_from_secret(sec), pub);
  struct stat st {};
  ASSERT_EQ(::stat((dir.path / "keys" / "server.secret").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  // Never overwrites.
  EXPECT_NE(daemon::generate_curve_keys(dir.path / "keys", keys).find("exists"), std::string::npos);

  std::ofstream(dir.path / "short.key") << "# comment\nabc\n";
  const std::string e = daemon::read_curve_key_file(dir.path / "short.key", pub);
  EXPECT_NE(e.find("short.key:2: a Z85 CURVE key has 40 characters"), std::string::npos) << e;
  EXPECT_NE(daemon::read_curve_key_file(dir.path / "missing.key", pub).find("--gen-keys"), std::string::npos);
}

// ------------------------------------------------------------------------ config

TEST(Config, FileSetsEveryKeyAndFlagsOverrideIt) {
  test::TempDir dir;
  const auto file = dir.path / "bodyd.json";
  std::ofstream(file) << R"({
    // comments are allowed
    "sources": ["replay:a.csv", "sim:b.bvh"], "fast": true, "replay_speed": 2.0, "loop": false,
    "exit_at_end": true, "sim": {"rate_hz": 72, "left_hand_rate_hz": 60, "position_noise_mm": 2, "seed": 7},
    "pub": "tcp://127.0.0.1:6000", "control": "none", "allow_remote": false, "curve_secret_key": "",
    "send_hwm": 50, "wait_for_subscriber": true, "endpoints_file": "e.json", "rate_hz": 30,
    "queue_capacity": 256, "queue_max_age_ms": 40, "method": "ik", "model": "m.safetensors", "skeleton": "s.bvh",
    "head_height_m": 1.6, "log_level": "debug",
    "offsets": {"left_hand": {"position_m": [0, 0, -0.1], "rotation_xyzw": [0, 0.7071068, 0, 0.7071068]}}
  })";
  daemon::DaemonConfig c;
  const std::string file_arg = file.string();
  const char* argv[] = {"bodyd", "--config", file_arg.c_str(), "--pub", "ipc:///tmp/x", "--rate-hz", "0",
                        "--offset", "head=0,0.1,0"};
  const auto r = daemon::parse_command_line(9, argv, c);
  ASSERT_EQ(r.action, daemon::CliResult::Action::Run);
  EXPECT_EQ(c.sources, (std::vector<std::string>{"replay:a.csv", "sim:b.bvh"}));
  EXPECT_TRUE(c.fast);
  EXPECT_EQ(c.replay_speed, 2.0);
  EXPECT_TRUE(c.exit_at_end);
  EXPECT_EQ(c.sim.rate_hz, 72);
  EXPECT_EQ(c.sim.role_rate_hz[1], 60);
  EXPECT_EQ(c.sim.position_noise_mm, 2);
  EXPECT_EQ(c.sim.seed, 7u);
  EXPECT_EQ(c.pub_endpoint, "ipc:///tmp/x");  // flag over file
  EXPECT_EQ(c.control_endpoint, "none");
  EXPECT_EQ(c.send_hwm, 50);
  EXPECT_TRUE(c.wait_for_subscriber);
  EXPECT_EQ(c.rate_hz, 0.0);  // flag over file
  EXPECT_EQ(c.queue_capacity, 256u);
  EXPECT_EQ(c.queue_max_age_ms, 40.0);
  EXPECT_EQ(c.method, "ik");
  EXPECT_EQ(c.model_path, "m.safetensors");
  EXPECT_EQ(c.skeleton_path, "s.bvh");
  EXPECT_EQ(daemon::configured_head_height_m(c), 1.6);
  EXPECT_EQ(c.log_level, "debug");
  ASSERT_TRUE(c.offsets[1]);
  EXPECT_NEAR(c.offsets[1]->position_m.z(), -0.1, 1e-12);
  EXPECT_NEAR(c.offsets[1]->rotation.y(), 0.7071068, 1e-6);
  ASSERT_TRUE(c.offsets[0]);
  EXPECT_NEAR(c.offsets[0]->position_m.y(), 0.1, 1e-12);
  EXPECT_FALSE(c.offsets[2]);

  // What --print-config writes reads back to the same configuration.
  daemon::DaemonConfig again;
  ASSERT_EQ(daemon::apply_config_json(daemon::config_to_json(c), "printed", again), "");
  EXPECT_EQ(daemon::config_to_json(again), daemon::config_to_json(c));
}

TEST(Config, ErrorsNameTheFileThePlaceAndTheKey) {
  test::TempDir dir;
  auto load = [&](const std::string& text) {
    std::ofstream(dir.path / "c.json") << text;
    daemon::DaemonConfig c;
    return daemon::load_config_file(dir.path / "c.json", c);
  };
  std::string e = load("{\n  \"fast\": true,\n  \"rate_hz\": ,\n}");
  EXPECT_NE(e.find("c.json:3:"), std::string::npos) << e;
  e = load(R"({"fastt": true})");
  EXPECT_NE(e.find("fastt: unknown key"), std::string::npos) << e;
  e = load(R"({"fast": "yes"})");
  EXPECT_NE(e.find("fast: expected true or false, got string"), std::string::npos) << e;
  e = load(R"({"send_hwm": 1.5})");
  EXPECT_NE(e.find("send_hwm: expected a"), std::string::npos) << e;
  e = load(R"({"queue_capacity": -4})");
  EXPECT_NE(e.find("queue_capacity: expected a non-negative integer"), std::string::npos) << e;
  e = load(R"({"offsets": {"left_foot": {}}})");
  EXPECT_NE(e.find("left_foot: unknown role"), std::string::npos) << e;
  e = load(R"({"offsets": {"head": {"rotation_xyzw": [0, 0, 0, 2]}}})");
  EXPECT_NE(e.find("unit quaternion"), std::string::npos) << e;
  e = load(R"({"sim": {"noise": 1}})");
  EXPECT_NE(e.find("sim.noise: unknown key"), std::string::npos) << e;
  e = load("[1, 2]");
  EXPECT_NE(e.find("must be a JSON object"), std::string::npos) << e;
  daemon::DaemonConfig c;
  EXPECT_NE(daemon::load_config_file(dir.path / "none.json", c).find("cannot open"), std::string::npos);
}

TEST(Config, ValidationAndOffsetFlags) {
  daemon::DaemonConfig c;
  EXPECT_EQ(daemon::validate_config(c), "");
  c.method = "magic";
  EXPECT_NE(daemon::validate_config(c).find("diffusion or ik"), std::string::npos);
  c = {};
  c.user_height_m = 175;  // centimetres by mistake
  EXPECT_NE(daemon::validate_config(c).find("metres"), std::string::npos);
  c = {};
  c.user_height_m = 1.8;
  EXPECT_EQ(daemon::validate_config(c), "");
  EXPECT_NEAR(daemon::configured_head_height_m(c), 1.8 * daemon::kHeadHeightPerStature, 1e-12);
  c.head_height_m = 1.6;
  EXPECT_NE(daemon::validate_config(c).find("not both"), std::string::npos);
  c = {};
  c.loop = c.exit_at_end = true;
  EXPECT_NE(daemon::validate_config(c), "");

  EXPECT_EQ(daemon::parse_offset_flag("right_hand=0.01,-0.02,0.03,0,0,0,1", c), "");
  EXPECT_NEAR(c.offsets[2]->position_m.y(), -0.02, 1e-12);
  EXPECT_NE(daemon::parse_offset_flag("knee=0,0,0", c).find("unknown role"), std::string::npos);
  EXPECT_NE(daemon::parse_offset_flag("head=0,0", c).find("expected 3 numbers"), std::string::npos);
  EXPECT_NE(daemon::parse_offset_flag("head=0,x,0", c).find("\"x\" is not a number"), std::string::npos);
  EXPECT_NE(daemon::parse_offset_flag("head", c).find("ROLE=x,y,z"), std::string::npos);
}

TEST(Config, CommandLineErrorsExitWithUsageCode) {
  daemon::DaemonConfig c;
  const char* bad_flag[] = {"bodyd", "--no-such-flag"};
  EXPECT_EQ(daemon::parse_command_line(2, bad_flag, c).action, daemon::CliResult::Action::Exit);
  const char* bad_rate[] = {"bodyd", "--rate-hz", "-3"};
  auto r = daemon::parse_command_line(3, bad_rate, c);
  EXPECT_EQ(r.action, daemon::CliResult::Action::Exit);
  EXPECT_NE(r.exit_code, 0);
  const char* replay[] = {"bodyd", "--replay", "x.csv", "--sim", "y.bvh", "--source", "replay:z.csv"};
  daemon::DaemonConfig d;
  ASSERT_EQ(daemon::parse_command_line(7, replay, d).action, daemon::CliResult::Action::Run);
  EXPECT_EQ(d.sources, (std::vector<std::string>{"replay:z.csv", "replay:x.csv", "sim:y.bvh"}));
}

// Issue 11, item 2: a number that overflows never aborts; every integer is range-checked.
TEST(Config, OverflowingNumbersAreErrorsNotAborts) {
  test::TempDir dir;
  auto load = [&](const std::string& text) {
    std::ofstream(dir.path / "c.json", std::ios::trunc) << text;
    daemon::DaemonConfig c;
    return daemon::load_config_file(dir.path / "c.json", c);
  };
  std::string e = load(R"({"rate_hz": 1e400})");  // used to throw json::out_of_range: exit 134
  EXPECT_NE(e.find("c.json"), std::string::npos) << e;
  EXPECT_NE(e.find("overflow"), std::string::npos) << e;
  e = load(R"({"sim": {"seed": 1e400}})");
  EXPECT_NE(e.find("overflow"), std::string::npos) << e;
  e = load(R"({"send_hwm": 3000000000})");  // used to wrap to a negative int: "must be >= 1"
  EXPECT_NE(e.find("send_hwm: 3000000000 is out of range"), std::string::npos) << e;
  e = load(R"({"sim": {"seed": 18446744073709551615}})");  // the largest uint64: fits
  EXPECT_EQ(e, "") << e;
  e = load(R"({"sim": {"seed": -1}})");
  EXPECT_NE(e.find("non-negative"), std::string::npos) << e;
  e = load(R"({"queue_capacity": 99999999999999999999})");  // beyond uint64: a float in JSON
  EXPECT_NE(e.find("queue_capacity"), std::string::npos) << e;
  e = load(R"({"offsets": {"left_hand": {"position_m": [1e300, 0, 0]}}})");
  EXPECT_NE(e.find("offsets.left_hand"), std::string::npos) << e;
  EXPECT_NE(e.find("within +-2 m"), std::string::npos) << e;
  // Through the process: exit 2 with the message, not an abort.
  std::ofstream(dir.path / "c.json", std::ios::trunc) << R"({"rate_hz": 1e400})";
  const std::string config_path = (dir.path / "c.json").string();
  const char* argv[] = {"bodyd", "--config", config_path.c_str()};
  daemon::DaemonConfig c;
  const auto r = daemon::parse_command_line(3, argv, c);
  EXPECT_EQ(r.action, daemon::CliResult::Action::Exit);
  EXPECT_EQ(r.exit_code, 2);
}

TEST(Config, LimitsOnRatesSpeedsAndOffsets) {
  daemon::DaemonConfig c;
  c.rate_hz = 1e300;
  EXPECT_NE(daemon::validate_config(c).find("rate_hz"), std::string::npos);
  // Issue 43 item 12: 0 (every head sample) or at least one pose in 10 s; 1e-12 published every pose.
  for (double ok : {0.0, limits::kMinPoseRateHz, limits::kMaxRateHz}) {
    c.rate_hz = ok;
    EXPECT_EQ(daemon::validate_config(c), "") << ok;
  }
  c.rate_hz = 1e-12;
  EXPECT_NE(daemon::validate_config(c).find("rate_hz"), std::string::npos);
  const char* tiny_rate[] = {"bodyd", "--rate-hz", "1e-12"};
  daemon::DaemonConfig t;
  const auto tiny = daemon::parse_command_line(3, tiny_rate, t);
  EXPECT_EQ(tiny.action, daemon::CliResult::Action::Exit);
  EXPECT_EQ(tiny.exit_code, 2);
  c = {};
  c.replay_speed = 1e300;
  EXPECT_NE(daemon::validate_config(c).find("--speed"), std::string::npos);
  EXPECT_NE(daemon::parse_offset_flag("left_hand=1e300,0,0", c).find("within +-2 m"), std::string::npos);
  EXPECT_NE(daemon::parse_offset_flag("left_hand=inf,0,0", c), "");
  EXPECT_FALSE(c.offsets[1].has_value());
  EXPECT_EQ(daemon::parse_offset_flag("left_hand=2,-2,0.5", c), "");  // the limit itself is fine
}

TEST(Config, QueueMaxAge) {
  daemon::DaemonConfig c;
  EXPECT_EQ(c.queue_max_age_ms, 100.0);  // on by default (docs/daemon.md)
  EXPECT_EQ(daemon::validate_config(c), "");
  c.queue_max_age_ms = 0;  // off
  EXPECT_EQ(daemon::validate_config(c), "");
  for (double bad : {-1.0, 60001.0, std::nan("")}) {
    c.queue_max_age_ms = bad;
    EXPECT_NE(daemon::validate_config(c).find("queue_max_age_ms"), std::string::npos) << bad;
  }
  const char* argv[] = {"bodyd", "--queue-max-age-ms", "250"};
  daemon::DaemonConfig f;
  const auto r = daemon::parse_command_line(3, argv, f);
  EXPECT_EQ(r.action, daemon::CliResult::Action::Run);
  EXPECT_EQ(f.queue_max_age_ms, 250.0);
}

// Issue 11, item 9: every bad command line exits 2, as docs/daemon.md says (CLI11 used 105, 109).
TEST(Config, EveryBadCommandLineExits2) {
  for (std::vector<const char*> argv : {std::vector<const char*>{"bodyd", "--speed", "0"},
                                        std::vector<const char*>{"bodyd", "--bogus"},
                                        std::vector<const char*>{"bodyd", "--send-hwm", "0"},
                                        std::vector<const char*>{"bodyd", "--rate-hz", "abc"},
                                        std::vector<const char*>{"bodyd", "--speed", "1e300"}}) {
    daemon::DaemonConfig c;
    const auto r = daemon::parse_command_line(static_cast<int>(argv.size()), argv.data(), c);
    EXPECT_EQ(r.action, daemon::CliResult::Action::Exit) << argv[1];
    EXPECT_EQ(r.exit_code, 2) << argv[1];
  }
  daemon::DaemonConfig c;
  const char* help[] = {"bodyd", "--help"};
  EXPECT_EQ(daemon::parse_command_line(2, help, c).exit_code, 0);
}

// Issue 20 item 7: a malformed --source or --output spec is a bad command line (2), found
// before anything is opened; a well-formed one still runs.
TEST(Config, MalformedSourceAndOutputSpecsExit2) {
  for (std::vector<const char*> argv :
       {std::vector<const char*>{"bodyd", "--source", "bogus:x"}, std::vector<const char*>{"bodyd", "--source", "vmc:abc"},
        std::vector<const char*>{"bodyd", "--source", "vmc:127.0.0.1:99999"},
        std::vector<const char*>{"bodyd", "--source", "vrchat:9001?nope=1"},
        std::vector<const char*>{"bodyd", "--source", "udp:"}, std::vector<const char*>{"bodyd", "--source", "hid:zz:1"},
        std::vector<const char*>{"bodyd", "--source", "replay:"},
        std::vector<const char*>{"bodyd", "--output", "nosuch:127.0.0.1:9000"},
        std::vector<const char*>{"bodyd", "--output", "vrchat:127.0.0.1:70000"},
        std::vector<const char*>{"bodyd", "--output", "vrchat:127.0.0.1:9000?slots=wings"},
        std::vector<const char*>{"bodyd", "--output", "vmc:127.0.0.1:39539?rate=fast"}}) {
    daemon::DaemonConfig c;
    testing::internal::CaptureStderr();
    const auto r = daemon::parse_command_line(static_cast<int>(argv.size()), argv.data(), c);
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_EQ(r.action, daemon::CliResult::Action::Exit) << argv[2];
    EXPECT_EQ(r.exit_code, 2) << argv[2];
    EXPECT_NE(err.find(argv[2]), std::string::npos) << err;  // the message names the spec
  }
  const char* good[] = {"bodyd", "--source", "vmc:39539?head=HMD-1", "--source", "hid:1209:B0D1", "--output",
                        "vrchat:127.0.0.1:9000?slots=hip,feet&rate=60"};
  daemon::DaemonConfig c;
  EXPECT_EQ(daemon::parse_command_line(7, good, c).action, daemon::CliResult::Action::Run);
}

// Issue 11, item 3: an ipc:// endpoint never replaces a file that is not a socket, and the
// socket directory must be private.
TEST(Endpoint, IpcNeverReplacesAFileAndNeedsAPrivateDirectory) {
  test::TempDir dir;
  ::chmod(dir.path.c_str(), 0700);
  std::ofstream(dir.path / "f.txt") << "data\n";
  std::string e = daemon::prepare_ipc_endpoint("ipc://" + (dir.path / "f.txt").string(), "--pub");
  EXPECT_NE(e.find("exists and is not a socket"), std::string::npos) << e;
  std::ifstream in(dir.path / "f.txt");
  std::string text;
  std::getline(in, text);
  EXPECT_EQ(text, "data");
  std::filesystem::create_directory(dir.path / "d");
  e = daemon::prepare_ipc_endpoint("ipc://" + (dir.path / "d").string(), "--pub");
  EXPECT_NE(e.find("is a directory"), std::string::npos) << e;
  EXPECT_EQ(e.find("another bodyd"), std::string::npos) << e;
  std::filesystem::create_symlink(dir.path / "f.txt", dir.path / "link");
  e = daemon::prepare_ipc_endpoint("ipc://" + (dir.path / "link").string(), "--pub");
  EXPECT_NE(e.find("not a socket"), std::string::npos) << e;

  EXPECT_EQ(daemon::check_private_directory(dir.path), "");
  std::filesystem::create_directory(dir.path / "open");
  ::chmod((dir.path / "open").c_str(), 0777);
  e = daemon::check_private_directory(dir.path / "open");
  EXPECT_NE(e.find("open to other users (mode 0777)"), std::string::npos) << e;
  std::filesystem::create_directory_symlink(dir.path / "d", dir.path / "dlink");
  e = daemon::check_private_directory(dir.path / "dlink");
  EXPECT_NE(e.find("symbolic link"), std::string::npos) << e;
  // A directory bodyd creates is private even under a permissive umask.
  const mode_t old = ::umask(0);
  e = daemon::prepare_ipc_endpoint("ipc://" + (dir.path / "new" / "pose").string(), "--pub");
  ::umask(old);
  EXPECT_EQ(e, "");
  struct stat st {};
  ASSERT_EQ(::stat((dir.path / "new").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0700u);
}

// Issue 11, item 4: reload-model loads only the configured model or files under the models directory.
TEST(Config, ReloadModelOnlyFromTheModelsDirectory) {
  test::TempDir dir;
  std::filesystem::create_directories(dir.path / "models");
  std::ofstream(dir.path / "models" / "a.safetensors") << "x";
  std::ofstream(dir.path / "mine.safetensors") << "x";
  daemon::DaemonConfig c;
  c.models_dir = (dir.path / "models").string();
  c.model_path = (dir.path / "mine.safetensors").string();
  EXPECT_EQ(daemon::check_reload_model_path(dir.path / "models" / "a.safetensors", c), "");
  EXPECT_EQ(daemon::check_reload_model_path(dir.path / "mine.safetensors", c), "");
  for (const auto& bad : {std::filesystem::path("/etc/shadow"), dir.path / "models" / ".." / "other.safetensors",
                          dir.path / "models"}) {
    const std::string e = daemon::check_reload_model_path(bad, c);
    EXPECT_NE(e.find("not under the models directory"), std::string::npos) << bad << ": " << e;
  }
  std::filesystem::create_symlink("/etc/passwd", dir.path / "models" / "link.safetensors");
  EXPECT_NE(daemon::check_reload_model_path(dir.path / "models" / "link.safetensors", c), "");
}

// Issue 11, item 8: the documented loopback forms bind.
TEST(Endpoint, LocalhostAndBracketedIpv6Bind) {
  bool ipv6 = false;
  EXPECT_EQ(daemon::zmq_bind_address("tcp://localhost:5570", ipv6), "tcp://127.0.0.1:5570");
  EXPECT_FALSE(ipv6);
  EXPECT_EQ(daemon::zmq_bind_address("tcp://[::1]:5570", ipv6), "tcp://[::1]:5570");
  EXPECT_TRUE(ipv6);
  EXPECT_EQ(daemon::zmq_bind_address("ipc:///tmp/x", ipv6), "ipc:///tmp/x");
  EXPECT_FALSE(ipv6);
  zmq::context_t ctx;
  zmq::socket_t s(ctx, zmq::socket_type::pub);
  s.set(zmq::sockopt::linger, 0);
  EXPECT_NO_THROW(s.bind(daemon::zmq_bind_address("tcp://localhost:*", ipv6)));
  zmq::socket_t s6(ctx, zmq::socket_type::pub);
  s6.set(zmq::sockopt::linger, 0);
  const std::string a6 = daemon::zmq_bind_address("tcp://[::1]:*", ipv6);
  s6.set(zmq::sockopt::ipv6, ipv6 ? 1 : 0);
  try {
    s6.bind(a6);
  } catch (const zmq::error_t& e) {
    // A machine without IPv6 on loopback cannot bind [::1] at all; anything else is a failure.
    if (e.num() != EADDRNOTAVAIL) ADD_FAILURE() << e.what();
  }
}

// ------------------------------------------------------------------------ control requests

class RecordingTarget final : public daemon::ControlTarget {
 public:
  std::string last;
  double height = -1;
  std::optional<std::string> path;
  nlohmann::json status() override { return reply("status"); }
  nlohmann::json skeleton() override { return reply("skeleton"); }
  nlohmann::json calibrate_height(double h) override {
    height = h;
    return reply("calibrate_height");
  }
  nlohmann::json calibrate_from_head() override { return reply("calibrate_from_head"); }
  nlohmann::json reload_model(const std::optional<std::string>& p) override {
    path = p;
    return reply("reload_model");
  }
  nlohmann::json shutdown() override { return reply("shutdown"); }

 private:
  nlohmann::json reply(const std::string& what) {
    last = what;
    return {{"ok", true}, {"did", what}};
  }
};

TEST(Control, DispatchesWellFormedRequests) {
  RecordingTarget t;
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"status"})", t)["did"], "status");
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"skeleton"})", t)["did"], "skeleton");
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"shutdown"})", t)["did"], "shutdown");
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"calibrate","head_height_m":1.6})", t)["did"], "calibrate_height");
  EXPECT_DOUBLE_EQ(t.height, 1.6);
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"calibrate","user_height_m":1.8})", t)["ok"], true);
  EXPECT_DOUBLE_EQ(t.height, 1.8 * daemon::kHeadHeightPerStature);
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"calibrate","user_height_m":0})", t)["ok"], true);
  EXPECT_DOUBLE_EQ(t.height, 0.0);
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"calibrate","from":"head"})", t)["did"], "calibrate_from_head");
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"reload-model"})", t)["did"], "reload_model");
  EXPECT_FALSE(t.path);
  EXPECT_EQ(daemon::handle_control_request(R"({"cmd":"reload-model","path":"m.safetensors"})", t)["ok"], true);
  EXPECT_EQ(t.path, "m.safetensors");
}

TEST(Control, MalformedRequestsGetAnErrorAndCallNothing) {
  const std::pair<const char*, const char*> cases[] = {
      {"", "not valid JSON"},
      {"status", "not valid JSON"},
      {"{\"cmd\":\"status\"", "not valid JSON"},
      {"\xff\xfe", "not valid JSON"},
      {"[\"status\"]", "JSON object"},
      {"42", "JSON object"},
      {"{}", "missing \"cmd\""},
      {R"({"command":"status"})", "missing \"cmd\""},
      {R"({"cmd":5})", "\"cmd\" must be a string"},
      {R"({"cmd":null})", "\"cmd\" must be a string"},
      {R"({"cmd":"Status"})", "unknown cmd \"Status\""},
      {R"({"cmd":"status","verbose":true})", "unknown key \"verbose\""},
      {R"({"cmd":"calibrate"})", "exactly one of"},
      {R"({"cmd":"calibrate","user_height_m":1.8,"from":"head"})", "exactly one of"},
      {R"({"cmd":"calibrate","user_height_m":"tall"})", "must be a number"},
      {R"({"cmd":"calibrate","user_height_m":180})", "between 0.5 and 2.6"},
      {R"({"cmd":"calibrate","head_height_m":-1})", "between 0.5 and 2.6"},
      {R"({"cmd":"calibrate","from":"hands"})", "must be \"head\""},
      {R"({"cmd":"calibrate","from":1})", "must be \"head\""},
      {R"({"cmd":"reload-model","path":7})", "non-empty string"},
      {R"({"cmd":"reload-model","path":""})", "non-empty string"},
  };
  for (const auto& [request, expected] : cases) {
    RecordingTarget t;
    const nlohmann::json reply = daemon::handle_control_request(request, t);
    EXPECT_EQ(reply["ok"], false) << request;
    ASSERT_TRUE(reply.contains("error")) << request;
    EXPECT_NE(reply["error"].get<std::string>().find(expected), std::string::npos)
        << request << " -> " << reply["error"];
    EXPECT_EQ(t.last, "") << request;
  }
}

// ------------------------------------------------------------------------ sources

struct CollectingSink final : drivers::SampleSink {
  SampleQueue queue{1 << 16};
  void push(const SourceSample& s) override { queue.push(s); }
  bool push_wait(const SourceSample& s, std::chrono::nanoseconds t) override { return queue.push_wait(s, t); }
};

TEST(ReplaySource, PacedFollowsTheTimestampsAndRestampsToHostTime) {
  const auto samples = test::synthetic_samples(20, 200.0);  // 95 ms of samples
  drivers::ReplayOptions options;
  options.speed = 1.0;
  auto source = drivers::make_replay_source("test", samples, options);
  CollectingSink sink;
  const std::int64_t start = drivers::monotonic_ns();
  ASSERT_EQ(source->start(sink, 3), "");
  SourceSample s;
  std::vector<SourceSample> got;
  while (got.size() < samples.size() && sink.queue.pop(s, 1s)) got.push_back(s);
  ASSERT_EQ(got.size(), samples.size());
  // Not early: the last sample comes no sooner than the log's span after the start (how late
  // a paced replay delivers depends on the machine: bodyd-bench-stop measures it).
  const std::int64_t elapsed = got.back().arrival_ns - start;
  EXPECT_GE(elapsed, samples.back().t_ns - samples.front().t_ns);
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].source_index, 3);
    EXPECT_EQ(got[i].sample.role, samples[i].role);
    EXPECT_EQ(got[i].sample.position_m, samples[i].position_m);
    // Restamped: host time from the start on (not the log's), same spacing as the log, never
    // after the arrival.
    EXPECT_EQ(got[i].sample.t_ns - got[0].sample.t_ns, samples[i].t_ns - samples[0].t_ns);
    EXPECT_GE(got[i].sample.t_ns, start);
    EXPECT_LE(got[i].sample.t_ns, got[i].arrival_ns);
  }
  for (int i = 0; i < 50 && !source->status().finished; ++i) std::this_thread::sleep_for(10ms);
  EXPECT_TRUE(source->status().finished);
  EXPECT_EQ(source->status().samples, samples.size());
}

TEST(ReplaySource, FastIsLosslessThroughATinyQueueAndKeepsLogTime) {
  const auto samples = test::synthetic_samples(500);
  drivers::ReplayOptions options;
  options.paced = false;
  auto source = drivers::make_replay_source("test", samples, options);
  SampleQueue queue(16);
  ASSERT_EQ(source->start(queue, 0), "");
  SourceSample s;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    ASSERT_TRUE(queue.pop(s, 2s)) << i;
    ASSERT_EQ(s.sample.t_ns, samples[i].t_ns) << i;
  }
  EXPECT_EQ(queue.dropped(), 0u);
}

// A replay source that loops `samples` as fast as it can.
std::unique_ptr<drivers::TrackerSource> fast_loop_source(const std::string& name, const std::vector<TrackerSample>& samples) {
  drivers::ReplayOptions options;
  options.paced = false;
  options.loop = true;
  return drivers::make_replay_source(name, samples, options);
}

TEST(ReplaySource, LoopKeepsTimeIncreasingAndStopIsPrompt) {
  const auto samples = test::synthetic_samples(10);
  auto source = fast_loop_source("test", samples);
  SampleQueue queue(8);
  ASSERT_EQ(source->start(queue, 0), "");
  std::array<std::int64_t, kRoleCount> last{INT64_MIN, INT64_MIN, INT64_MIN};
  SourceSample s;
  for (int i = 0; i < 100; ++i) {  // 3+ loops
    ASSERT_TRUE(queue.pop(s, 2s));
    EXPECT_GT(s.sample.t_ns, last[static_cast<int>(s.sample.role)]);
    last[static_cast<int>(s.sample.role)] = s.sample.t_ns;
  }
  // The source is now blocked on a full queue; stop() must still return, without the queue
  // being drained (how long it takes: bodyd-bench-stop).
  EXPECT_TRUE(test::returns_within([&] { source->stop(); }, 10s));

  // A paced source waiting for a far-away sample stops too, long before the sample is due,
  // and never delivers it.
  std::vector<TrackerSample> far = test::synthetic_samples(1);
  far.push_back(far.front());
  far.back().t_ns += 60'000'000'000;  // a minute later
  drivers::ReplayOptions wait_a_minute;
  wait_a_minute.max_gap_s = 120;  // the minute is waited for, not shortened to a gap
  auto paced = drivers::make_replay_source("far", far, wait_a_minute);
  SampleQueue far_queue(8);
  ASSERT_EQ(paced->start(far_queue, 0), "");
  for (std::size_t i = 0; i + 1 < far.size(); ++i) ASSERT_TRUE(far_queue.pop(s, 2s)) << i;
  EXPECT_TRUE(test::returns_within([&] { paced->stop(); }, 10s));
  EXPECT_FALSE(far_queue.pop(s, 0ms));
}

// Issue 11, item 6: a jump forward in a paced replay's log time is replayed as a short gap,
// logged and shown in status, not an hour of silence.
TEST(ReplaySource, PacedJumpForwardIsReplayedAsAGapAndReported) {
  auto samples = test::synthetic_samples(20, 200.0);
  for (std::size_t i = samples.size() / 2; i < samples.size(); ++i) samples[i].t_ns += 3'600'000'000'000;  // an hour
  drivers::ReplayOptions options;
  options.max_gap_s = 0.1;
  auto source = drivers::make_replay_source("jump", samples, options);
  CollectingSink sink;
  ASSERT_EQ(source->start(sink, 0), "");
  SourceSample s;
  std::vector<SourceSample> got;
  while (got.size() < samples.size() && sink.queue.pop(s, 3s)) got.push_back(s);
  ASSERT_EQ(got.size(), samples.size());
  const std::size_t k = samples.size() / 2;
  const std::int64_t gap_ns = got[k].sample.t_ns - got[k - 1].sample.t_ns;  // restamped host times
  EXPECT_GE(gap_ns, 100'000'000 - (samples[k - 1].t_ns - samples[k - 2].t_ns));
  EXPECT_LT(gap_ns, 2'000'000'000);
  EXPECT_NE(source->status().last_error.find("jumps forward by 3600"), std::string::npos) << source->status().last_error;
}

// Issue 11, item 11: looping over times near the limit never overflows: the time base starts over.
TEST(ReplaySource, FastLoopNearTheTimeLimitNeverOverflows) {
  const std::int64_t t0 = limits::kMaxAbsTimeNs - 200'000'000;  // 0.2 s before the limit
  const auto samples = test::synthetic_samples(10, 90.0, t0);
  auto source = fast_loop_source("edge", samples);
  SampleQueue queue(64);
  ASSERT_EQ(source->start(queue, 0), "");
  SourceSample s;
  int backwards = 0;
  std::int64_t last = INT64_MIN;
  for (int i = 0; i < 300; ++i) {
    ASSERT_TRUE(queue.pop(s, 2s));
    ASSERT_TRUE(limits::time_plausible(s.sample.t_ns)) << i << ": " << s.sample.t_ns;
    if (s.sample.t_ns < last) ++backwards;
    last = s.sample.t_ns;
  }
  source->stop();
  EXPECT_GE(backwards, 1);
  EXPECT_NE(source->status().last_error.find("starts over"), std::string::npos) << source->status().last_error;
}

// Issue 11, item 9: a directory is not "no such tracker log".
TEST(OpenSource, ADirectoryAsTheLogSaysSo) {
  test::TempDir dir;
  std::string error;
  EXPECT_FALSE(drivers::open_replay_source(dir.path, {}, error));
  EXPECT_NE(error.find("is a directory"), std::string::npos) << error;
  EXPECT_EQ(error.find("no such"), std::string::npos) << error;
}

TEST(OpenSource, SpecsAndErrors) {
  std::string error;
  auto spec = drivers::parse_source_spec("replay:/x/y.csv", error);
  ASSERT_TRUE(spec);
  EXPECT_EQ(spec->scheme->scheme, "replay");
  EXPECT_EQ(spec->argument, "/x/y.csv");
  EXPECT_FALSE(drivers::parse_source_spec("replay:", error));
  EXPECT_NE(error.find("missing file"), std::string::npos);
  EXPECT_FALSE(drivers::parse_source_spec("/x/y.csv", error));
  EXPECT_NE(error.find("unknown kind"), std::string::npos);
  EXPECT_FALSE(drivers::open_source("replay:/no/such/log.csv", {}, error));
  EXPECT_NE(error.find("/no/such/log.csv"), std::string::npos);

  test::TempDir dir;
  std::ofstream(dir.path / "bad.csv") << "# bodyd-tracker-log v1\nt_ns,role,valid,px,py,pz,qx,qy,qz,qw\n0,head,1,0,1\n";
  EXPECT_FALSE(drivers::open_source("replay:" + (dir.path / "bad.csv").string(), {}, error));
  EXPECT_NE(error.find("bad.csv:3"), std::string::npos) << error;

  // The bundled recording opens and holds all three roles at 90 Hz.
  auto bundled = drivers::open_source("replay:" + daemon::bundled_recording_path().string(), {}, error);
  ASSERT_TRUE(bundled) << error;
}

// Issue 19 item 2: the --source help names every registered scheme (io/sources.cpp),
// as the unknown-kind error does (tests/drivers/source_registry_test.cpp).
TEST(OpenSource, HelpListsEverySource) {
  daemon::DaemonConfig c;
  const char* help[] = {"bodyd", "--help"};
  testing::internal::CaptureStdout();
  const auto r = daemon::parse_command_line(2, help, c);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_EQ(r.exit_code, 0);
  const std::size_t at = out.find("tracker source: ");
  ASSERT_NE(at, std::string::npos) << out;
  const std::string line = out.substr(at, out.find('\n', at) - at);
  EXPECT_NE(line.find(drivers::source_syntax_list(", ")), std::string::npos) << line;
  for (const drivers::SourceScheme& s : drivers::source_schemes())
    EXPECT_NE(line.find(std::string(s.syntax)), std::string::npos) << s.syntax << " is not in: " << line;
}

TEST(OpenSource, SimulatedDevicesFromABvhClip) {
  drivers::SourceOptions options;
  options.replay.paced = false;
  options.sim.rate_hz = 60;
  std::string error;
  auto source = drivers::open_source("sim:" + (test::fixtures() / "walk_60.bvh").string(), options, error);
  ASSERT_TRUE(source) << error;
  SampleQueue queue(1024);
  ASSERT_EQ(source->start(queue, 0), "");
  for (int i = 0; i < 100 && !source->status().finished; ++i) std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(source->status().finished);
  // 60 frames at 30 fps = 1.967 s -> 119 samples per role at 60 Hz, as the simulator computes.
  const Motion motion = read_bvh(test::fixtures() / "walk_60.bvh");
  EXPECT_EQ(queue.size(), simulate_trackers(motion, options.sim).size());
  EXPECT_FALSE(drivers::open_source("sim:/no/such.bvh", options, error));
  options.sim.rate_hz = -1;
  EXPECT_FALSE(drivers::open_source("sim:" + (test::fixtures() / "walk_60.bvh").string(), options, error));
  EXPECT_NE(error.find("rate"), std::string::npos) << error;
}

}  // namespace
}  // namespace bodyd
