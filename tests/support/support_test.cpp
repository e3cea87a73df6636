// The test-support library itself: each helper does what its header says, and can say no.
#include "bodyd/test/files.h"
#include "bodyd/test/net.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"
#include "bodyd/test/wait.h"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <thread>

namespace bodyd::test {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

TEST(TestSupport, TempDirIsFreshPrivateAndRemovedWithItsContent) {
  fs::path kept;
  {
    TempDir a("bodyd-support");
    TempDir b("bodyd-support");
    EXPECT_NE(a.path, b.path);
    EXPECT_TRUE(fs::is_directory(a.path));
    EXPECT_EQ(a.path.filename().string().rfind("bodyd-support-", 0), 0u) << a.path;
    EXPECT_EQ(fs::status(a.path).permissions() & fs::perms::others_all, fs::perms::none);
    ASSERT_TRUE(write_file(a.path / "x.txt", "one\ntwo"));
    EXPECT_EQ(read_file(a.path / "x.txt"), "one\ntwo");
    EXPECT_EQ(read_file_bytes(a.path / "x.txt"), (std::vector<std::uint8_t>{'o', 'n', 'e', '\n', 't', 'w', 'o'}));
    fs::create_directories(a.path / "sub/deeper");
    kept = a.path;
  }
  EXPECT_FALSE(fs::exists(kept));
  EXPECT_EQ(read_file(kept / "x.txt"), "");  // a file that cannot be read reads as empty
  EXPECT_FALSE(write_file(kept / "x.txt", "no directory"));
}

TEST(TestSupport, ProcessExitCodeOutputsEnvironmentAndDirectory) {
  TempDir dir;
  ::setenv("BODYD_SUPPORT_TEST_GONE", "here", 1);
  const RunResult r = run({"/bin/sh", "-c", "echo out:$BODYD_SUPPORT_TEST_SET:${BODYD_SUPPORT_TEST_GONE-unset}:$(pwd); echo err >&2; exit 7"},
                          {.env = {{"BODYD_SUPPORT_TEST_SET", "yes"}, {"BODYD_SUPPORT_TEST_GONE", kUnset}},
                           .cwd = dir.path,
                           .output_dir = dir.path,
                           .name = "sh"});
  ::unsetenv("BODYD_SUPPORT_TEST_GONE");
  EXPECT_EQ(r.exit_code, 7);
  EXPECT_EQ(r.out, "out:yes:unset:" + fs::canonical(dir.path).string() + "\n");
  EXPECT_EQ(r.err, "err\n");
  EXPECT_EQ(read_file(dir.path / "sh.stdout"), r.out);
  EXPECT_THROW(Process({"/nonexistent/program"}, {.output_dir = dir.path}), std::runtime_error);
  EXPECT_THROW(Process({"/bin/true"}, {}), std::logic_error);  // no place for its output
}

TEST(TestSupport, ProcessWaitsSignalsAndIsKilledWhenDestroyed) {
  TempDir dir;
  pid_t pid = -1;
  {
    Process p({"/bin/sleep", "60"}, {.stdout_path = "/dev/null", .stderr_path = dir.path / "err"});
    pid = p.pid();
    EXPECT_TRUE(p.running());
    EXPECT_FALSE(p.wait(50).has_value());
    EXPECT_EQ(::kill(pid, 0), 0);
  }
  EXPECT_NE(::kill(pid, 0), 0);  // killed and reaped
  Process p({"/bin/sleep", "60"}, {.output_dir = dir.path});
  EXPECT_EQ(p.terminate(10000), 128 + SIGTERM);
  EXPECT_FALSE(p.running());
  Process search({"true"}, {.output_dir = dir.path, .search_path = true});
  EXPECT_EQ(search.wait(10000), 0);
}

TEST(TestSupport, ShellAndWaitForFile) {
  const ShellResult r = shell("printf 'a\\nb'; exit 3");
  EXPECT_EQ(r.status, 3);
  EXPECT_EQ(r.out, "a\nb");
  TempDir dir;
  EXPECT_FALSE(wait_for_file(dir.path / "f", 50).has_value());
  ASSERT_TRUE(write_file(dir.path / "f", "partial"));
  EXPECT_FALSE(wait_for_file(dir.path / "f", 50).has_value());  // no complete line yet
  std::thread writer([&] {
    std::this_thread::sleep_for(50ms);
    (void)write_file(dir.path / "f", "whole\n");
  });
  EXPECT_EQ(wait_for_file(dir.path / "f", 10000), "whole\n");
  writer.join();
}

TEST(TestSupport, WaitingForAnEventSaysWhetherItCame) {
  std::atomic<bool> flag{false};
  EXPECT_FALSE(eventually([&] { return flag.load(); }, 30ms));
  std::thread setter([&] {
    std::this_thread::sleep_for(20ms);
    flag = true;
  });
  EXPECT_TRUE(eventually([&] { return flag.load(); }, 10000ms));
  setter.join();
  bool ran = false;
  EXPECT_TRUE(returns_within([&] { ran = true; }, 10000ms));
  EXPECT_TRUE(ran);
  EXPECT_FALSE(returns_within([] { std::this_thread::sleep_for(200ms); }, 1ms));
}

TEST(TestSupport, LoopbackPortsAndConnections) {
  const int port = free_loopback_port(SOCK_STREAM);
  ASSERT_GT(port, 0);
  EXPECT_EQ(connect_loopback(port), -1);  // nobody listens there
  const int listener = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  ASSERT_EQ(::bind(listener, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0) << "the free port was not free";
  ASSERT_EQ(::listen(listener, 1), 0);
  const int fd = connect_loopback(port);
  EXPECT_GE(fd, 0);
  if (fd >= 0) ::close(fd);
  ::close(listener);
  EXPECT_GT(free_loopback_port(SOCK_DGRAM), 0);
}

}  // namespace
}  // namespace bodyd::test
