// The CURVE allow-list (--curve-allow DIR, docs/daemon.md "Security"): a client whose public
// key is in DIR gets poses and control answers; one with another key, or without CURVE, gets
// nothing. Keys made by bodyd --gen-keys (server) and --gen-keys DIR --client NAME.
#include "bodyd/io/zmq/curve_allow.h"
#include "bodyd/io/zmq/endpoint.h"
#include "bodyd/protocol/pose_message.h"
#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"
#include "../daemon_programs.h"
#include "../test_paths.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <thread>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// bodyd with CURVE on both sockets: its key pair in dir/server, the allow-list dir/allow,
// ephemeral ports, the endpoints written to dir/endpoints.json.
std::vector<std::string> curve_bodyd_args(const fs::path& dir) {
  return {kBodyd, "--method", "ik", "--pub", "tcp://127.0.0.1:0", "--control", "tcp://127.0.0.1:0",
          "--curve-secret-key", (dir / "server/server.secret").string(), "--curve-allow", (dir / "allow").string(),
          "--endpoints-file", (dir / "endpoints.json").string()};
}

std::string key_of(const fs::path& file) {
  std::string key;
  if (std::string e = daemon::read_curve_key_file(file, key); !e.empty()) throw std::runtime_error(e);
  return key;
}

// Whether a SUB socket with the given client secret key (empty: no CURVE) receives a pose
// within timeout_ms.
bool receives_pose(const std::string& endpoint, const std::string& server_public, const std::string& client_secret,
                   int timeout_ms) {
  zmq::context_t ctx;
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  if (!client_secret.empty()) {
    sub.set(zmq::sockopt::curve_serverkey, server_public);
    sub.set(zmq::sockopt::curve_publickey, daemon::curve_public_from_secret(client_secret));
    sub.set(zmq::sockopt::curve_secretkey, client_secret);
  }
  sub.set(zmq::sockopt::subscribe, std::string(protocol::kPoseTopic));
  sub.connect(endpoint);
  zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
  if (zmq::poll(&item, 1, std::chrono::milliseconds(timeout_ms)) <= 0) return false;
  zmq::message_t topic;
  return sub.recv(topic, zmq::recv_flags::dontwait).has_value() && topic.to_string_view() == protocol::kPoseTopic;
}

TEST(CurveAllowList, ListedKeyGetsPosesUnknownKeyGetsNothing) {
  TempDir dir;
  ASSERT_EQ(run({kBodyd, "--gen-keys", (dir.path / "server").string()}, {.output_dir = dir.path}).exit_code, 0);
  const RunResult alice = run({kBodyd, "--gen-keys", (dir.path / "clients").string(), "--client", "alice"},
                              {.output_dir = dir.path});
  ASSERT_EQ(alice.exit_code, 0) << alice.err;
  EXPECT_NE(alice.out.find("clients/alice.public (copy into bodyd's --curve-allow directory)"), std::string::npos)
      << alice.out;
  ASSERT_EQ(run({kBodyd, "--gen-keys", (dir.path / "clients").string(), "--client", "mallory"}, {.output_dir = dir.path})
                .exit_code,
            0);
  // The allow-list holds alice's public key only.
  fs::create_directories(dir.path / "allow");
  fs::copy_file(dir.path / "clients/alice.public", dir.path / "allow/alice.public");

  Process bodyd(curve_bodyd_args(dir.path), {.output_dir = dir.path, .name = "bodyd"});
  const auto endpoints = wait_for_file(dir.path / "endpoints.json", 20000);
  ASSERT_TRUE(endpoints) << bodyd.log();
  const json e = json::parse(*endpoints);
  const std::string pub = e["pub"], control = e["control"];
  const std::string server_public = key_of(dir.path / "server/server.public");
  EXPECT_EQ(e["curve_public_key"], server_public);

  EXPECT_TRUE(receives_pose(pub, server_public, key_of(dir.path / "clients/alice.secret"), 10000)) << bodyd.log();
  EXPECT_FALSE(receives_pose(pub, server_public, key_of(dir.path / "clients/mallory.secret"), 1500));
  EXPECT_FALSE(receives_pose(pub, "", "", 1000));

  // The control socket too, through bodyd-ctl.
  const std::vector<std::string> ctl{kCtl, "--control", control, "--timeout-s", "2", "--curve-server-key",
                                     (dir.path / "server/server.public").string(), "--curve-client-key"};
  auto with_key = [&](const std::string& name) {
    auto args = ctl;
    args.push_back((dir.path / "clients" / (name + ".secret")).string());
    args.push_back("status");
    return run(args, {.output_dir = dir.path, .name = "ctl"});
  };
  const RunResult ok = with_key("alice");
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_NE(ok.out.find("CURVE on"), std::string::npos) << ok.out;
  const RunResult refused = with_key("mallory");
  EXPECT_EQ(refused.exit_code, 3) << refused.out << refused.err;
  EXPECT_NE(refused.err.find("--curve-allow"), std::string::npos) << refused.err;

  bodyd.signal(SIGTERM);
  EXPECT_EQ(bodyd.wait(10000), 0) << bodyd.log();
  // bodyd said whom it refused, naming the key.
  EXPECT_NE(bodyd.err().find("refused client key " + daemon::curve_public_from_secret(key_of(dir.path / "clients/mallory.secret"))),
            std::string::npos)
      << bodyd.err();
}

TEST(CurveAllowList, BadSetupsAreClearErrors) {
  TempDir dir;
  ASSERT_EQ(run({kBodyd, "--gen-keys", (dir.path / "server").string()}, {.output_dir = dir.path}).exit_code, 0);
  fs::create_directories(dir.path / "empty");
  // An allow-list without a server key.
  RunResult r = run({kBodyd, "--curve-allow", (dir.path / "empty").string(), "--print-config"}, {.output_dir = dir.path});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("needs curve_secret_key"), std::string::npos) << r.err;
  // An empty directory: nobody could connect.
  r = run({kBodyd, "--method", "ik", "--pub", "tcp://127.0.0.1:0", "--control", "none", "--curve-secret-key",
           (dir.path / "server/server.secret").string(), "--curve-allow", (dir.path / "empty").string()},
          {.output_dir = dir.path}, 20000);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no client keys"), std::string::npos) << r.err;
  // --client without --gen-keys, and a bad name.
  EXPECT_EQ(run({kBodyd, "--client", "alice"}, {.output_dir = dir.path}).exit_code, 2);
  EXPECT_EQ(run({kBodyd, "--gen-keys", (dir.path / "k").string(), "--client", "../x"}, {.output_dir = dir.path}).exit_code, 2);
}

TEST(CurveAllowList, LoaderReadsPublicFilesAndNamesABadOne) {
  TempDir dir;
  daemon::CurveKeyPair a, b;
  ASSERT_EQ(daemon::generate_curve_keys(dir.path, a, "a"), "");
  ASSERT_EQ(daemon::generate_curve_keys(dir.path, b, "b"), "");
  std::set<std::string> keys;
  std::vector<std::string> skipped;
  ASSERT_EQ(daemon::load_curve_allow_dir(dir.path, keys, skipped), "");
  EXPECT_EQ(keys, (std::set<std::string>{a.public_key, b.public_key}));
  EXPECT_EQ(skipped, (std::vector<std::string>{"a.secret", "b.secret"}));
  std::ofstream(dir.path / "c.public") << "not a key\n";
  keys.clear();
  const std::string e = daemon::load_curve_allow_dir(dir.path, keys, skipped);
  EXPECT_NE(e.find("c.public"), std::string::npos) << e;
}

// Issue 20 item 7: a NAME.public that is a symbolic link is refused, saying so (it would admit a
// key kept anywhere).
TEST(CurveAllowList, APublicSymlinkIsRefused) {
  TempDir dir;
  daemon::CurveKeyPair a, elsewhere;
  fs::create_directories(dir.path / "allow");
  fs::create_directories(dir.path / "other");
  ASSERT_EQ(daemon::generate_curve_keys(dir.path / "allow", a, "a"), "");
  ASSERT_EQ(daemon::generate_curve_keys(dir.path / "other", elsewhere, "x"), "");
  fs::create_symlink(dir.path / "other/x.public", dir.path / "allow/x.public");
  std::set<std::string> keys;
  std::vector<std::string> skipped;
  const std::string e = daemon::load_curve_allow_dir(dir.path / "allow", keys, skipped);
  EXPECT_NE(e.find("x.public is a symbolic link"), std::string::npos) << e;
  EXPECT_NE(e.find("refused"), std::string::npos) << e;
  EXPECT_EQ(keys.count(elsewhere.public_key), 0u);
}

// Issue 20 item 7: the .secret-in-the-allow-list warning once (both sockets load the list), and
// refused handshakes logged at a limited rate: 200 clients with made-up keys give a handful of
// lines, not one each.
TEST(CurveAllowList, WarningsOnceAndRefusalsAtALimitedRate) {
  TempDir dir;
  ASSERT_EQ(run({kBodyd, "--gen-keys", (dir.path / "server").string()}, {.output_dir = dir.path}).exit_code, 0);
  ASSERT_EQ(run({kBodyd, "--gen-keys", (dir.path / "allow").string(), "--client", "alice"}, {.output_dir = dir.path})
                .exit_code,
            0);  // alice.secret stays in the allow-list directory: a mistake worth a warning
  Process bodyd(curve_bodyd_args(dir.path), {.output_dir = dir.path, .name = "bodyd"});
  const auto endpoints = wait_for_file(dir.path / "endpoints.json", 20000);
  ASSERT_TRUE(endpoints) << bodyd.log();
  const json e = json::parse(*endpoints);
  const std::string server_public = key_of(dir.path / "server/server.public");
  {
    zmq::context_t ctx;
    std::vector<zmq::socket_t> clients;
    for (int i = 0; i < 200; ++i) {
      char pub[41], secret[41];
      ASSERT_EQ(zmq_curve_keypair(pub, secret), 0);
      zmq::socket_t sub(ctx, zmq::socket_type::sub);
      sub.set(zmq::sockopt::linger, 0);
      sub.set(zmq::sockopt::curve_serverkey, server_public);
      sub.set(zmq::sockopt::curve_publickey, std::string(pub));
      sub.set(zmq::sockopt::curve_secretkey, std::string(secret));
      sub.set(zmq::sockopt::subscribe, "");
      sub.connect(e["pub"].get<std::string>());
      clients.push_back(std::move(sub));
    }
    // Until bodyd has refused at least 128 handshakes (it says so at each power of two); up to 30 s,
    // since a loaded machine retries the handshakes slowly (10 s was once too few in a test run).
    for (int i = 0; i < 600 && bodyd.err().find("128 refused so far") == std::string::npos; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  bodyd.signal(SIGTERM);
  ASSERT_EQ(bodyd.wait(10000), 0) << bodyd.log();
  const std::string err = bodyd.err();
  ASSERT_NE(err.find("128 refused so far"), std::string::npos) << err;
  auto count = [&](const std::string& what) {
    std::size_t n = 0;
    for (auto at = err.find(what); at != std::string::npos; at = err.find(what, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count("alice.secret is a secret key"), 1u) << err;
  // The first 8 keys once each, then the 16th, 32nd, 64th, 128th refusal (before: 200 lines).
  EXPECT_LE(count("refused client key"), 12u) << err;
}

}  // namespace
}  // namespace bodyd::test
