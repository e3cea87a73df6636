// End to end: the bodyd daemon with --source over simulated HID and USB devices
// (BODYD_FAKE_DEVICES: the drivers read simulated devices through fake transports)
// publishing to a ZeroMQ subscriber; --list-devices; and a missing device, which the
// daemon reports and waits for.
#include "bodyd/protocol/pose_message.h"

#include "../test_paths.h"
#include "pose_sub_helpers.h"

#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include <signal.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <thread>

namespace bodyd {
namespace {

namespace fs = std::filesystem;

using test::read_file;
using test::TempDir;

// bodyd as a child process, stdout and stderr in files, with `fake_bvh` as BODYD_FAKE_DEVICES
// (unset when empty).
class Daemon : public test::Process {
 public:
  Daemon(std::vector<std::string> args, const fs::path& dir, const std::string& fake_bvh)
      : Process(with_bodyd(std::move(args)), {.env = {{"BODYD_FAKE_DEVICES", fake_bvh.empty() ? test::kUnset : fake_bvh}},
                                              .stdout_path = dir / "stdout",
                                              .stderr_path = dir / "stderr"}) {}

 private:
  static std::vector<std::string> with_bodyd(std::vector<std::string> args) {
    args.insert(args.begin(), BODYD_EXE);
    return args;
  }
};

std::string fake_clip() { return (test::fixtures() / "walk_60.bvh").string(); }

std::optional<nlohmann::json> wait_endpoints(const fs::path& file, int timeout_ms) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < end) {
    auto j = nlohmann::json::parse(read_file(file), nullptr, false);
    if (!j.is_discarded() && j.contains("pub")) return j;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return std::nullopt;
}

// Receives poses until one has every flag in `want` (or the timeout); returns how many came.
int receive_until(zmq::socket_t& sub, std::uint32_t want, int timeout_ms, bool& out_found) {
  out_found = false;
  int count = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < end) {
    const std::optional<protocol::PoseMessage> next = test::poll_pose(sub, std::chrono::milliseconds(50));
    if (!next) continue;
    const protocol::PoseMessage& pose = *next;
    ++count;
    if ((pose.flags & want) == want) {
      out_found = true;
      return count;
    }
  }
  return count;
}

void run_pipeline(const std::vector<std::string>& sources) {
  TempDir dir;
  std::vector<std::string> args{"--method", "ik", "--pub", "tcp://127.0.0.1:*", "--control", "none",
                                "--endpoints-file", (dir.path / "endpoints.json").string()};
  for (const auto& s : sources) {
    args.push_back("--source");
    args.push_back(s);
  }
  Daemon daemon(args, dir.path, fake_clip());
  const auto endpoints = wait_endpoints(dir.path / "endpoints.json", 10000);
  ASSERT_TRUE(endpoints) << daemon.err();
  zmq::context_t ctx;
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::subscribe, "");
  sub.connect((*endpoints)["pub"].get<std::string>());
  const std::uint32_t all = protocol::kFlagHeadValid | protocol::kFlagLeftHandValid | protocol::kFlagRightHandValid;
  bool found = false;
  const int received = receive_until(sub, all, 10000, found);
  EXPECT_TRUE(found) << "poses received: " << received << "\n" << daemon.err();
  daemon.signal(SIGINT);
  EXPECT_EQ(daemon.wait(5000), 0) << daemon.err();
  for (const auto& s : sources) EXPECT_NE(daemon.err().find(s + ": opened"), std::string::npos) << s;
}

TEST(DaemonWithDevices, SimulatedHidHeadsetAndHydraToSubscriber) {
  run_pipeline({"hid:1209:B0D2", "hid:1532:0300"});
}

TEST(DaemonWithDevices, SimulatedUsbTrackerToSubscriber) { run_pipeline({"usb:1209:B0D1"}); }

TEST(DaemonWithDevices, ListDevices) {
  TempDir dir;
  Daemon with_fakes({"--list-devices"}, dir.path, fake_clip());
  ASSERT_EQ(with_fakes.wait(10000), 0) << with_fakes.err();
  for (const char* spec : {"hid:1209:B0D1", "hid:1209:B0D2", "hid:1532:0300", "usb:1209:B0D1"})
    EXPECT_NE(with_fakes.out().find(spec), std::string::npos) << with_fakes.out();

  TempDir dir2;
  Daemon real({"--list-devices"}, dir2.path, "");
  ASSERT_EQ(real.wait(10000), 0) << real.err();
  // This machine may or may not have a tracker; either way the answer is plain.
  const std::string out = real.out();
  EXPECT_TRUE(out.find("no tracker device found") != std::string::npos || out.find("hid:") != std::string::npos ||
              out.find("usb:") != std::string::npos)
      << out;
  // With nothing found it names the bundled recording where this bodyd finds it (the source tree's).
  if (out.find("no tracker device found") != std::string::npos) {
    EXPECT_NE(out.find("bodyd --source replay:" + (test::source_dir() / "data/demo/walk.csv").string()), std::string::npos)
        << out;
    EXPECT_NE(out.find("bodyd --source vrchat:"), std::string::npos) << out;
  }
}

TEST(DaemonWithDevices, MissingDeviceIsReportedAndAwaited) {
  TempDir dir;
  // The real hidapi transport; 1209:0001 is a pid.codes test ID no tracker ships with.
  Daemon daemon({"--method", "ik", "--pub", "tcp://127.0.0.1:*", "--control", "none", "--source", "hid:1209:0001"},
                dir.path, "");
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (daemon.err().find("no HID device 1209:0001 found") == std::string::npos &&
         std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_NE(daemon.err().find("no HID device 1209:0001 found"), std::string::npos) << daemon.err();
  EXPECT_FALSE(daemon.wait(300).has_value()) << "the daemon should keep waiting\n" << daemon.err();
  daemon.signal(SIGTERM);
  EXPECT_EQ(daemon.wait(5000), 0) << daemon.err();
}

}  // namespace
}  // namespace bodyd
