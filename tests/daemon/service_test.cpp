// bodyd under systemd, without systemd (docs/install.md): the test binds the NOTIFY_SOCKET
// datagram socket itself and checks READY=1, the watchdog pings and STOPPING=1; the user
// config read by --user-config (what the unit runs).
#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"
#include "../daemon_programs.h"
#include "../test_paths.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sys/socket.h>
#include <sys/un.h>
#include <poll.h>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <thread>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// The service manager's end of NOTIFY_SOCKET: a bound AF_UNIX datagram socket.
class NotifySocket {
 public:
  explicit NotifySocket(const fs::path& path) : path_(path) {
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof(addr.sun_path), "%s", path.c_str());
    if (fd_ < 0 || bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0)
      throw std::runtime_error("cannot bind " + path.string());
  }
  ~NotifySocket() { close(fd_); }
  // The next datagram within timeout_ms, or nullopt.
  std::optional<std::string> receive(int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return std::nullopt;
    char buf[4096];
    const ssize_t n = recv(fd_, buf, sizeof(buf), 0);
    if (n < 0) return std::nullopt;
    return std::string(buf, static_cast<std::size_t>(n));
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
  int fd_ = -1;
};

bool has_line(const std::string& message, const std::string& line) {
  std::istringstream in(message);
  std::string l;
  while (std::getline(in, l))
    if (l == line) return true;
  return false;
}

std::vector<std::string> bodyd_args(const fs::path& dir) {
  return {kBodyd, "--method", "ik", "--pub", "ipc://" + (dir / "pose").string(), "--control",
          "ipc://" + (dir / "control").string()};
}

TEST(SystemdNotify, ReadyThenWatchdogPingsThenStopping) {
  TempDir dir;
  NotifySocket notify(dir.path / "notify");
  // 200 ms watchdog: bodyd pings every 100 ms.
  Process bodyd(bodyd_args(dir.path), {.env = {{"NOTIFY_SOCKET", notify.path().string()}, {"WATCHDOG_USEC", "200000"},
                                               {"WATCHDOG_PID", kUnset}},
                                       .output_dir = dir.path, .name = "bodyd"});
  const auto ready = notify.receive(10000);
  ASSERT_TRUE(ready) << bodyd.log();
  EXPECT_TRUE(has_line(*ready, "READY=1")) << *ready;
  EXPECT_NE(ready->find("STATUS=publishing poses on ipc://"), std::string::npos) << *ready;

  int pings = 0;
  const auto start = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - start < std::chrono::milliseconds(1000)) {
    const auto m = notify.receive(300);
    if (m && has_line(*m, "WATCHDOG=1")) ++pings;
  }
  // About 10 in a second; at least 3 leaves room for a loaded machine, none would fail.
  EXPECT_GE(pings, 3);
  EXPECT_LE(pings, 20);

  const RunResult shutdown = run({kCtl, "--control", "ipc://" + (dir.path / "control").string(), "shutdown"},
                                 {.output_dir = dir.path, .name = "ctl"});
  EXPECT_EQ(shutdown.exit_code, 0) << shutdown.err;
  bool stopping = false;
  while (auto m = notify.receive(5000)) {
    if (has_line(*m, "STOPPING=1")) {
      stopping = true;
      break;
    }
  }
  EXPECT_TRUE(stopping);
  EXPECT_EQ(bodyd.wait(10000), 0) << bodyd.log();
}

TEST(SystemdNotify, NoWatchdogPingsWithoutWatchdogUsec) {
  TempDir dir;
  NotifySocket notify(dir.path / "notify");
  Process bodyd(bodyd_args(dir.path), {.env = {{"NOTIFY_SOCKET", notify.path().string()}, {"WATCHDOG_USEC", kUnset}},
                                       .output_dir = dir.path, .name = "bodyd"});
  const auto ready = notify.receive(10000);
  ASSERT_TRUE(ready) << bodyd.log();
  EXPECT_TRUE(has_line(*ready, "READY=1"));
  const auto next = notify.receive(600);
  EXPECT_FALSE(next && has_line(*next, "WATCHDOG=1")) << *next;
  bodyd.signal(SIGTERM);
  EXPECT_EQ(bodyd.wait(10000), 0) << bodyd.log();
}

TEST(SystemdNotify, StartFailureIsReportedAndNotReady) {
  TempDir dir;
  NotifySocket notify(dir.path / "notify");
  const RunResult r = run({kBodyd, "--method", "diffusion", "--model", (dir.path / "missing.safetensors").string(),
                           "--pub", "ipc://" + (dir.path / "pose").string(), "--control", "none"},
                          {.env = {{"NOTIFY_SOCKET", notify.path().string()}}, .output_dir = dir.path, .name = "bodyd"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  const auto m = notify.receive(100);
  ASSERT_TRUE(m);
  EXPECT_FALSE(has_line(*m, "READY=1")) << *m;
  EXPECT_NE(m->find("STATUS=failed to start: "), std::string::npos) << *m;
}

// --user-config reads $XDG_CONFIG_HOME/bodyd/config.json; flags still override it.
TEST(UserConfig, ReadFromXdgConfigHomeAndOverriddenByFlags) {
  TempDir dir;
  fs::create_directories(dir.path / "config/bodyd");
  std::ofstream(dir.path / "config/bodyd/config.json") << "// a user's config\n{\"method\": \"ik\", \"rate_hz\": 30}\n";
  const ProcessOptions env{.env = {{"XDG_CONFIG_HOME", (dir.path / "config").string()}}, .output_dir = dir.path};
  RunResult r = run({kBodyd, "--user-config", "--print-config"}, env);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  json printed = json::parse(r.out);
  EXPECT_EQ(printed["method"], "ik");
  EXPECT_EQ(printed["rate_hz"], 30.0);
  r = run({kBodyd, "--user-config", "--rate-hz", "45", "--print-config"}, env);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out)["rate_hz"], 45.0);
  // Without --user-config the file is not read.
  r = run({kBodyd, "--print-config"}, env);
  EXPECT_EQ(json::parse(r.out)["method"], "diffusion");
}

TEST(UserConfig, MissingFileMeansDefaultsAndABadOneIsAnError) {
  TempDir dir;
  ProcessOptions env{.env = {{"XDG_CONFIG_HOME", (dir.path / "config").string()}}, .output_dir = dir.path};
  RunResult r = run({kBodyd, "--user-config", "--print-config"}, env);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out)["method"], "diffusion");
  fs::create_directories(dir.path / "config/bodyd");
  std::ofstream(dir.path / "config/bodyd/config.json") << "{\n  \"method\": \"ik\",\n  \"rate_hz\": \"fast\"\n}\n";
  r = run({kBodyd, "--user-config", "--print-config"}, env);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find((dir.path / "config/bodyd/config.json").string() + ": rate_hz"), std::string::npos) << r.err;
  // XDG_CONFIG_HOME unset: ~/.config.
  env.env = {{"XDG_CONFIG_HOME", kUnset}, {"HOME", dir.path.string()}};
  fs::create_directories(dir.path / ".config/bodyd");
  std::ofstream(dir.path / ".config/bodyd/config.json") << "{\"rate_hz\": 20}\n";
  r = run({kBodyd, "--user-config", "--print-config"}, env);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out)["rate_hz"], 20.0);
}

// The example config shipped in share/doc/bodyd loads as it is.
TEST(UserConfig, ShippedExampleLoads) {
  TempDir dir;
  const RunResult r = run({kBodyd, "--config", (source_dir() / "packaging/config.example.json").string(), "--print-config"},
                          {.output_dir = dir.path});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out)["control"], "ipc:///tmp/bodyd/control");
}

// Issue 43 item 15: the setups the example config and the README's quick start show are valid:
// each commented-out "sources" line of the example, uncommented, loads and names what it says,
// and each `bodyd --source ...` command of the README passes bodyd's checks of its specs.
TEST(UserConfig, TheSetupsTheExampleAndTheReadmeShowLoad) {
  TempDir dir;
  const std::string example = read_file(source_dir() / "packaging/config.example.json");
  int setups = 0;
  std::istringstream lines(example);
  for (std::string line; std::getline(lines, line);) {
    const std::size_t at = line.find("// \"sources\":");
    if (at == std::string::npos) continue;
    const std::string keys = line.substr(at + 3);  // "sources": [...], "outputs": [...],
    std::string text = example;
    text.replace(text.find(line), line.size(), keys);
    ASSERT_TRUE(write_file(dir.path / "config.json", text));
    const RunResult r = run({kBodyd, "--config", (dir.path / "config.json").string(), "--print-config"},
                            {.output_dir = dir.path});
    ASSERT_EQ(r.exit_code, 0) << keys << ": " << r.err;
    const json printed = json::parse(r.out);
    const json expected = json::parse("{" + keys.substr(0, keys.rfind(',')) + "}");
    EXPECT_EQ(printed["sources"], expected["sources"]) << keys;
    if (expected.contains("outputs")) {
      EXPECT_EQ(printed["outputs"], expected["outputs"]) << keys;
    }
    ++setups;
  }
  EXPECT_GE(setups, 4) << "steamvr, monado, vrchat and hid";
  const std::string readme = read_file(source_dir() / "README.md");
  int commands = 0;
  for (std::size_t at = readme.find("bodyd --source "); at != std::string::npos;
       at = readme.find("bodyd --source ", at + 1)) {
    const std::string command = readme.substr(at, readme.find_first_of("`\n", at) - at);
    const ShellResult r = shell("'" + kBodyd + "'" + command.substr(5) + " --print-config 2>&1 >/dev/null");
    EXPECT_EQ(r.status, 0) << "README.md: " << command << ": " << r.out;
    ++commands;
  }
  EXPECT_GE(commands, 4) << "steamvr, monado, vrchat and hid";
}

// Issue 43 item 13: only `--user-config` (the systemd unit) kept the calibration; a plain
// `bodyd ...`, as the docs show it, forgot it at every restart ("head default"). Now every way
// of starting bodyd reads and writes $XDG_STATE_HOME/bodyd/mounting.json (by default
// ~/.local/state/bodyd/mounting.json) unless a mounting file is configured; "none": nowhere.
TEST(StateFile, EveryWayOfStartingBodydKeepsTheCalibration) {
  TempDir dir;
  // What a calibration pose of an earlier session kept: the head height (no device measured).
  json roles = json::object();
  for (const char* role : {"head", "left_hand", "right_hand"})
    roles[role] = {{"measured", false}, {"position_m", {0, 0, 0}}, {"rotation_xyzw", {0, 0, 0, 1}}};
  const std::string kept =
      json{{"format", "bodyd-mounting v1"}, {"calibrated", "2026-12-02T10:00:00Z"}, {"head_height_m", 1.55}, {"roles", roles}}
          .dump();
  const fs::path state_home = dir.path / "state", home = dir.path / "home";
  for (const fs::path& folder : {state_home / "bodyd", home / ".local/state/bodyd"}) {
    fs::create_directories(folder);
    ASSERT_TRUE(write_file(folder / "mounting.json", kept));
  }
  struct Way {
    std::string name;
    std::vector<std::string> flags;
    std::map<std::string, std::string> env;
    std::string file;  // status's mounting.file; "" for none
  };
  const std::map<std::string, std::string> xdg{{"XDG_STATE_HOME", state_home.string()},
                                               {"XDG_CONFIG_HOME", (dir.path / "config").string()}};
  const std::vector<Way> ways = {
      {"plain bodyd", {}, xdg, (state_home / "bodyd/mounting.json").string()},
      {"bodyd --user-config (the systemd unit)", {"--user-config"}, xdg, (state_home / "bodyd/mounting.json").string()},
      {"XDG_STATE_HOME unset", {}, {{"XDG_STATE_HOME", kUnset}, {"HOME", home.string()}},
       (home / ".local/state/bodyd/mounting.json").string()},
      {"--mounting-file none", {"--mounting-file", "none"}, xdg, ""},
  };
  for (const Way& way : ways) {
    SCOPED_TRACE(way.name);
    std::vector<std::string> args = bodyd_args(dir.path);
    args.insert(args.end(), way.flags.begin(), way.flags.end());
    Process bodyd(args, {.env = way.env, .output_dir = dir.path, .name = "bodyd"});
    zmq::context_t ctx;
    const std::optional<std::string> reply = status_reply(ctx, "ipc://" + (dir.path / "control").string(), 20000);
    ASSERT_TRUE(reply) << bodyd.log();
    const json status = json::parse(*reply);
    EXPECT_EQ(status["mounting"]["file"], way.file) << status["mounting"].dump();
    if (way.file.empty()) {
      EXPECT_NE(status["calibration_source"], "file");
    } else {
      EXPECT_EQ(status["calibration_source"], "file") << bodyd.log();
      EXPECT_NEAR(status["head_height_m"].get<double>(), 1.55, 1e-9);
    }
    bodyd.signal(SIGTERM);
    EXPECT_EQ(bodyd.wait(10000), 0) << bodyd.log();
  }
  // --print-config shows where (a config written from it keeps "none").
  RunResult r = run({kBodyd, "--print-config"}, {.env = xdg, .output_dir = dir.path});
  EXPECT_EQ(json::parse(r.out)["mounting_file"], (state_home / "bodyd/mounting.json").string());
  r = run({kBodyd, "--mounting-file", "none", "--print-config"}, {.env = xdg, .output_dir = dir.path});
  EXPECT_EQ(json::parse(r.out)["mounting_file"], "none");
}

}  // namespace
}  // namespace bodyd::test
