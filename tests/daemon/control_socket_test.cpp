// The control socket against hostile and careless peers (issue 11 item 7): garbage on a raw TCP
// connection, left open or closed at once, a ZeroMQ 1.0 peer whose message has no envelope, a
// peer that asks and never reads: none of them may cost another client its answer.
#include "bodyd/daemon/daemon.h"
#include "bodyd/motion/tracker_log.h"
#include "fake_reconstructor.h"
#include "zmq_helpers.h"

#include "bodyd/test/net.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <random>
#include <thread>

namespace bodyd {
namespace {

using daemon::Daemon;
using daemon::DaemonConfig;

const bool kQuietLogs = (spdlog::set_level(spdlog::level::warn), true);

bool send_all(int fd, const std::string& bytes) {
  std::size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return false;
    sent += static_cast<std::size_t>(n);
  }
  return true;
}

// ZMTP 1.0 framing (rfc.zeromq.org/spec/13): a length byte counting the flags byte, the flags
// (bit 0: more frames follow), the body. libzmq talks 1.0 to any peer whose first byte is not 0xFF.
std::string zmtp10_frame(const std::string& body, bool more) {
  std::string f;
  f += static_cast<char>(body.size() + 1);
  f += static_cast<char>(more ? 1 : 0);
  return f + body;
}

class ControlSocketHostilePeers : public ::testing::Test {
 protected:
  void SetUp() override {
    write_tracker_log(dir.path / "log.csv", test::synthetic_samples(90));
    DaemonConfig c;
    c.sources = {"replay:" + (dir.path / "log.csv").string()};
    c.loop = true;
    c.method = "ik";
    c.wait_for_subscriber = false;
    c.pub_endpoint = "ipc://" + (dir.path / "pose").string();
    c.control_endpoint = "tcp://127.0.0.1:0";
    daemon_ = std::make_unique<Daemon>(c, [](const daemon::ModelChoice&, std::string&) -> std::unique_ptr<Reconstructor> {
      return std::make_unique<test::FakeReconstructor>();
    });
    ASSERT_EQ(daemon_->start(), "");
    runner = std::thread([&] { daemon_->run(); });
    const std::string& endpoint = daemon_->control_endpoint();
    port = std::stoi(endpoint.substr(endpoint.rfind(':') + 1));
  }
  void TearDown() override {
    for (int fd : open_fds) ::close(fd);
    daemon_->request_stop();
    if (runner.joinable()) runner.join();
  }
  // A status request from a normal client must be answered (3 s: the answer takes milliseconds;
  // a lost request never gets one).
  void expect_status_answered(const std::string& after) {
    auto reply = test::control_request(ctx, daemon_->control_endpoint(), R"({"cmd":"status"})", 3000);
    ASSERT_TRUE(reply) << "no answer to status after " << after;
    EXPECT_EQ((*reply)["ok"], true) << after;
  }
  // Sends `bytes` on a new raw connection, then closes it or leaves it open until TearDown.
  void raw_peer(const std::string& bytes, bool keep_open) {
    const int fd = test::connect_loopback(port);
    ASSERT_GE(fd, 0);
    send_all(fd, bytes);  // may fail once the daemon drops the connection: that is fine
    if (keep_open)
      open_fds.push_back(fd);
    else
      ::close(fd);
    // Give the daemon time to take the bytes and see the close before the next client asks.
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
  }

  test::TempDir dir;
  zmq::context_t ctx;
  std::unique_ptr<Daemon> daemon_;
  std::thread runner;
  int port = 0;
  std::vector<int> open_fds;
};

TEST_F(ControlSocketHostilePeers, RandomPayloadsNeverEatTheNextRequest) {
  expect_status_answered("nothing");
  std::mt19937 rng(11);
  for (int i = 0; i < 20; ++i) {
    std::string payload(4096, '\0');
    for (char& c : payload) c = static_cast<char>(rng() & 0xFF);
    // Half start with a byte libzmq reads as ZMTP 1.0 framing, half as a ZMTP 3 greeting.
    if (i % 2 == 1) payload[0] = static_cast<char>(0xFF);
    raw_peer(payload, /*keep_open=*/i % 3 == 0);
    expect_status_answered("random payload " + std::to_string(i));
  }
}

// The case that cost a REP socket its next answer: a peer's message with no envelope delimiter,
// the peer gone by the time the message is read.
TEST_F(ControlSocketHostilePeers, MessageWithoutEnvelopeFromAGonePeer) {
  for (int i = 0; i < 10; ++i) {
    const std::string identity = zmtp10_frame("", false);
    raw_peer(identity + zmtp10_frame("x", true) + zmtp10_frame("{\"cmd\":\"status\"}", false), /*keep_open=*/false);
    expect_status_answered("a message without a delimiter, round " + std::to_string(i));
  }
}

// A well-formed ZMTP 1.0 request is answered; a peer that asks again and again and never reads
// (its connection open) does not hold up anyone else.
TEST_F(ControlSocketHostilePeers, APeerThatNeverReadsItsAnswers) {
  const int fd = test::connect_loopback(port);
  ASSERT_GE(fd, 0);
  open_fds.push_back(fd);
  std::string request = zmtp10_frame("", true) + zmtp10_frame(R"({"cmd":"status"})", false);
  std::string bytes = zmtp10_frame("", false);
  for (int i = 0; i < 2000; ++i) bytes += request;
  ASSERT_TRUE(send_all(fd, bytes.substr(0, zmtp10_frame("", false).size() + request.size())));
  // Its first answer arrives, framed as ZMTP 1.0: [""] then the reply.
  // (libzmq's greeting comes first; read until the answer is complete or 3 s have passed.)
  timeval tv{0, 100'000};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  std::string got;
  for (int i = 0; i < 30 && got.find(R"("ok":true)") == std::string::npos; ++i) {
    char buf[4096];
    const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
    if (n > 0) got.append(buf, static_cast<std::size_t>(n));
  }
  EXPECT_NE(got.find(R"("ok":true)"), std::string::npos) << "a ZMTP 1.0 request got no answer";
  // Then thousands more it never reads.
  send_all(fd, bytes.substr(zmtp10_frame("", false).size() + request.size()));
  for (int i = 0; i < 5; ++i) expect_status_answered("a peer that never reads, round " + std::to_string(i));
}

}  // namespace
}  // namespace bodyd
