// cmake --install into a temporary prefix (docs/install.md): the layout, the files written
// for the prefix (systemd unit, pkg-config), and the installed bodyd running the bundled
// recording to a subscriber without touching the source or build trees (strace).
#include "../test_paths.h"
#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>
#include <regex>
#include <set>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;

const fs::path kBuildDir = BODYD_BUILD_DIR;
const fs::path kCmake = BODYD_CMAKE_COMMAND;
// A sanitizer build (make sanitize) installs instrumented libraries: a program built against them
// needs the sanitizers' runtime too, and LeakSanitizer refuses to run under ptrace (strace).
#if defined(__SANITIZE_ADDRESS__)
constexpr const char* kSanitizeFlags = " -fsanitize=address,undefined";
constexpr bool kSanitized = true;
#else
constexpr const char* kSanitizeFlags = "";
constexpr bool kSanitized = false;
#endif

// One install for every test of the suite (an install copies ~15 MB).
class InstallTree : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new TempDir("bodyd-install");
    prefix_ = scratch_->path / "prefix";
    const RunResult r =
        run({kCmake.string(), "--install", kBuildDir.string(), "--prefix", prefix_.string()},
            {.output_dir = scratch_->path, .name = "install"}, 180000);
    install_log_ = r.out + r.err;
    install_ok_ = r.exit_code == 0;
  }
  static void TearDownTestSuite() {
    delete scratch_;
    scratch_ = nullptr;
  }
  void SetUp() override { ASSERT_TRUE(install_ok_) << "cmake --install failed:\n" << install_log_; }

  static inline TempDir* scratch_ = nullptr;
  static inline fs::path prefix_;
  static inline std::string install_log_;
  static inline bool install_ok_ = false;
};

TEST_F(InstallTree, HasTheUsualLayout) {
  for (const char* file : {"bin/bodyd", "bin/bodyd-ctl", "bin/bodyd-sub", "bin/bodyd-viewer-bridge",
                           "include/bodyd_client.h", "share/bodyd/models/bodyd-default.safetensors",
                           "share/bodyd/data/demo/walk.csv", "share/bodyd/data/demo/skeleton.bvh",
                           "share/bodyd/viewer/index.html", "share/bodyd/viewer/viewer.js", "share/doc/bodyd/README.md",
                           "share/doc/bodyd/docs/install.md", "share/doc/bodyd/config.example.json",
                           "lib/systemd/user/bodyd.service", "lib/udev/rules.d/70-bodyd.rules"}) {
    EXPECT_TRUE(fs::is_regular_file(prefix_ / file)) << file;
  }
  // A test tool is not installed (issue 20 item 8: the package shipped bodyd-testpub).
  EXPECT_FALSE(fs::exists(prefix_ / "bin/bodyd-testpub"));
  // The client library and its pkg-config file, in whatever libdir GNUInstallDirs chose.
  bool lib = false, pc = false;
  for (const auto& e : fs::recursive_directory_iterator(prefix_ / "lib")) {
    lib |= e.path().filename() == "libbodyd_client.so";
    pc |= e.path().filename() == "bodyd-client.pc";
  }
  EXPECT_TRUE(lib);
  EXPECT_TRUE(pc);
  // The model is the one of the source tree, byte for byte.
  EXPECT_EQ(read_file(prefix_ / "share/bodyd/models/bodyd-default.safetensors"),
            read_file(source_dir() / "models/bodyd-default.safetensors"));
}

TEST_F(InstallTree, UnitAndPkgConfigNameThePrefixInstalledTo) {
  const std::string unit = read_file(prefix_ / "lib/systemd/user/bodyd.service");
  EXPECT_NE(unit.find("ExecStart=" + (prefix_ / "bin/bodyd").string() + " --user-config\n"), std::string::npos) << unit;
  EXPECT_NE(unit.find("Type=notify\n"), std::string::npos);
  EXPECT_NE(unit.find("WatchdogSec="), std::string::npos);
  EXPECT_EQ(unit.find('@'), std::string::npos) << "an unreplaced @VARIABLE@:\n" << unit;

  fs::path pc;
  for (const auto& e : fs::recursive_directory_iterator(prefix_ / "lib"))
    if (e.path().filename() == "bodyd-client.pc") pc = e.path();
  ASSERT_FALSE(pc.empty());
  const std::string text = read_file(pc);
  EXPECT_NE(text.find("prefix=" + prefix_.string() + "\n"), std::string::npos) << text;
  EXPECT_EQ(text.find('@'), std::string::npos) << text;
}

// The pkg-config file and the installed header and library build the C example, which then
// receives poses from the installed bodyd.
TEST_F(InstallTree, CExampleBuildsWithPkgConfigAndReceivesPoses) {
  fs::path pc_dir;
  for (const auto& e : fs::recursive_directory_iterator(prefix_ / "lib"))
    if (e.path().filename() == "bodyd-client.pc") pc_dir = e.path().parent_path();
  const RunResult flags = run({"/usr/bin/pkg-config", "--cflags", "--libs", "bodyd-client"},
                              {.env = {{"PKG_CONFIG_PATH", pc_dir.string()}}, .output_dir = scratch_->path, .name = "pc"});
  if (flags.exit_code != 0 && !fs::exists("/usr/bin/pkg-config")) GTEST_SKIP() << "pkg-config is not installed";
  ASSERT_EQ(flags.exit_code, 0) << flags.err;
  // pkg-config ends its output with a newline, which would end the shell command before kSanitizeFlags.
  std::string pc_flags = flags.out;
  while (!pc_flags.empty() && std::isspace(static_cast<unsigned char>(pc_flags.back()))) pc_flags.pop_back();
  TempDir dir("bodyd-cexample");
  // Split the flags on spaces (no path here holds one: mkdtemp under the temp directory).
  std::vector<std::string> cc{"/bin/sh", "-c",
                              "cc -std=c11 -o " + (dir.path / "sub").string() + " " +
                                  (prefix_ / "share/doc/bodyd/examples/c/bodyd_sub_c.c").string() + " " + pc_flags +
                                  kSanitizeFlags};
  const RunResult built = run(cc, {.output_dir = dir.path, .name = "cc"});
  ASSERT_EQ(built.exit_code, 0) << built.out << built.err;

  const std::string pub = "ipc://" + (dir.path / "pose").string();
  const std::string control = "ipc://" + (dir.path / "control").string();
  Process bodyd({(prefix_ / "bin/bodyd").string(), "--method", "ik", "--pub", pub, "--control", control},
                {.cwd = dir.path, .output_dir = dir.path, .name = "bodyd"});
  fs::path lib_dir = pc_dir.parent_path();
  Process sub({(dir.path / "sub").string(), pub, control},
              {.env = {{"LD_LIBRARY_PATH", lib_dir.string()}}, .output_dir = dir.path, .name = "sub"});
  int lines = 0;
  for (int i = 0; i < 1000 && lines < 20; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const std::string out = sub.out();
    lines = static_cast<int>(std::count(out.begin(), out.end(), '\n'));
  }
  EXPECT_GE(lines, 20) << sub.log() << bodyd.log();
  EXPECT_NE(sub.out().find("seq "), std::string::npos) << sub.log();
  sub.signal(SIGTERM);
  bodyd.signal(SIGTERM);
  EXPECT_EQ(bodyd.wait(5000), 0) << bodyd.log();
}

// Every path a traced process named in a file-related system call.
std::vector<std::string> traced_paths(const std::string& trace) {
  std::vector<std::string> paths;
  static const std::regex quoted(R"re("((?:[^"\\]|\\.)*)")re");
  std::istringstream in(trace);
  std::string line;
  while (std::getline(in, line))
    for (std::sregex_iterator it(line.begin(), line.end(), quoted), end; it != end; ++it) paths.push_back((*it)[1]);
  return paths;
}

// Whether the trace shows `path` opened successfully.
bool opened(const std::string& trace, const std::string& path) {
  std::istringstream in(trace);
  std::string line;
  while (std::getline(in, line))
    if (line.find("open") != std::string::npos && line.find('"' + path + '"') != std::string::npos &&
        line.find("= -1") == std::string::npos)
      return true;
  return false;
}

bool under(const std::string& path, const fs::path& dir) {
  const std::string d = dir.lexically_normal().string();
  const std::string base = d.back() == '/' ? d.substr(0, d.size() - 1) : d;
  return path == base || path.rfind(base + "/", 0) == 0;
}

TEST_F(InstallTree, InstalledBodydTouchesNothingInTheSourceOrBuildTree) {
  if (run({"/usr/bin/strace", "-f", "-o", "/dev/null", "/bin/true"}, {.output_dir = scratch_->path, .name = "probe"})
          .exit_code != 0)
    GTEST_SKIP() << "strace cannot trace here (not installed, or ptrace is not permitted, e.g. a container without "
                    "CAP_SYS_PTRACE)";
  TempDir dir("bodyd-traced");
  const std::string pub = "ipc://" + (dir.path / "pose").string();
  const fs::path trace = dir.path / "trace.txt", endpoints = dir.path / "endpoints.json";
  // Every file-related system call (open, stat, access, readlink, exec...), not only openat:
  // bodyd must not even look at the source tree. Paths up to 4096 characters.
  Process bodyd({"/usr/bin/strace", "-f", "-qq", "-s", "4096", "-e", "trace=%file", "-o", trace.string(),
                 (prefix_ / "bin/bodyd").string(), "--exit-at-end", "--fast", "--wait-for-subscriber", "--send-hwm",
                 "100000", "--pub", pub, "--control", "none", "--endpoints-file", endpoints.string()},
                {.env = {{"XDG_DATA_HOME", (dir.path / "xdg").string()},
                         {"ASAN_OPTIONS", kSanitized ? "detect_leaks=0" : bodyd::test::kUnset}},
                 .cwd = dir.path, .output_dir = dir.path, .name = "bodyd"});
  ASSERT_TRUE(wait_for_file(endpoints, 30000)) << bodyd.log();
  Process sub({(prefix_ / "bin/bodyd-sub").string(), "--endpoint", pub, "--json", "--timeout-s", "10", "--count", "732"},
              {.cwd = dir.path, .output_dir = dir.path, .name = "sub"});
  ASSERT_EQ(bodyd.wait(120000), 0) << bodyd.log();
  ASSERT_EQ(sub.wait(20000), 0) << sub.log();

  // The subscriber got every pose: one per head sample of the bundled recording (732, none
  // invalid), as bodyd's log says.
  const std::string out = sub.out();
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 732);
  EXPECT_NE(bodyd.err().find("every source has finished; 732 poses published"), std::string::npos) << bodyd.err();

  const std::string text = read_file(trace);
  const auto paths = traced_paths(text);
  ASSERT_FALSE(paths.empty()) << "strace recorded nothing";
  // Positive control: the trace shows the installed model and recording being opened.
  const std::string model = (prefix_ / "share/bodyd/models/bodyd-default.safetensors").string();
  const std::string recording = (prefix_ / "share/bodyd/data/demo/walk.csv").string();
  EXPECT_TRUE(opened(text, model)) << "the installed model was not opened";
  EXPECT_TRUE(opened(text, recording)) << "the installed recording was not opened";
  std::set<std::string> offending;
  for (const auto& p : paths)
    if (under(p, source_dir()) || under(p, kBuildDir)) offending.insert(p);
  std::string list;
  for (const auto& p : offending) list += "  " + p + "\n";
  EXPECT_TRUE(offending.empty()) << "the installed bodyd looked at the source or build tree:\n" << list;
}

// make package (issue 20 item 8) builds only what ships, in its own tree: configured with
// BODYD_BUILD_TESTS=OFF the build has the programs but no test, fuzz target or test tool
// (configure only: no compiler runs).
TEST(PackageBuild, WithoutTestsConfiguresOnlyWhatShips) {
  TempDir dir("bodyd-package-build");
  const fs::path tree = dir.path / "build-package";
  const RunResult configure = run({kCmake.string(), "-S", source_dir().string(), "-B", tree.string(),
                                   "-DBODYD_BUILD_TESTS=OFF", "-DCMAKE_BUILD_TYPE=RelWithDebInfo"},
                                  {.output_dir = dir.path, .name = "configure"}, 240000);
  ASSERT_EQ(configure.exit_code, 0) << configure.out << configure.err;
  const RunResult help = run({kCmake.string(), "--build", tree.string(), "--target", "help"},
                             {.output_dir = dir.path, .name = "help"}, 60000);
  ASSERT_EQ(help.exit_code, 0) << help.err;
  std::set<std::string> targets;
  std::istringstream lines(help.out);
  for (std::string line; std::getline(lines, line);)
    if (line.rfind("... ", 0) == 0) targets.insert(line.substr(4, line.find(' ', 4) - 4));
  for (const char* program : {"bodyd", "bodyd-ctl", "bodyd-sub", "bodyd-viewer-bridge", "bodyd_client"})
    EXPECT_TRUE(targets.count(program)) << program << " is not built for the package";
  for (const std::string& t : targets) {
    EXPECT_EQ(t.find("_test"), std::string::npos) << "a test in the package build: " << t;
    EXPECT_NE(t.rfind("fuzz_", 0), 0u) << "a fuzz target in the package build: " << t;
    EXPECT_NE(t, "bodyd-testpub");
  }
  EXPECT_FALSE(fs::exists(tree / "CTestTestfile.cmake")) << "ctest is configured in the package build";
}

// The Makefile's package recipe (make -n prints it without running it): its own build tree,
// tests off, setup told it is a package build.
TEST(PackageBuild, MakePackageUsesItsOwnTreeWithoutTests) {
  if (!fs::exists("/usr/bin/make")) GTEST_SKIP() << "make is not installed";
  TempDir dir("bodyd-make-n");
  const RunResult r = run({"/usr/bin/make", "-n", "-C", source_dir().string(), "package"},
                          {.output_dir = dir.path, .name = "make"}, 30000);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* part : {"BODYD_SETUP_PACKAGE=1 scripts/setup", "-B build-package", "-DBODYD_BUILD_TESTS=OFF",
                           "cd build-package && cpack -G DEB"})
    EXPECT_NE(r.out.find(part), std::string::npos) << "missing \"" << part << "\" in:\n" << r.out;
}

// scripts/setup for a package build asks only for build dependencies and never runs npm:
// dpkg-query and npm are replaced by fakes on PATH that log their arguments (the fake
// dpkg-query says every package is installed, so nothing is installed).
TEST(PackageBuild, SetupForAPackageSkipsTestPackagesAndNpm) {
  TempDir dir("bodyd-setup");
  const fs::path bin = dir.path / "bin", log = dir.path / "calls.log";
  fs::create_directories(bin);
  for (const char* name : {"dpkg-query", "npm", "chromium"}) {
    std::ofstream script(bin / name);
    script << "#!/bin/sh\necho \"" << name << " $*\" >> '" << log.string() << "'\n"
           << (std::string(name) == "dpkg-query" ? "printf 'install ok installed'\n" : "") << "exit 0\n";
    script.close();
    fs::permissions(bin / name, fs::perms::owner_all);
  }
  const RunResult r = run({"/bin/bash", (source_dir() / "scripts/setup").string()},
                          {.env = {{"PATH", bin.string() + ":/usr/bin:/bin"}, {"BODYD_SETUP_PACKAGE", "1"}},
                           .output_dir = dir.path, .name = "setup"},
                          30000);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const std::string calls = read_file(log);
  EXPECT_NE(calls.find("dpkg-query -W -f=${Status} libzmq3-dev"), std::string::npos) << calls;
  EXPECT_NE(calls.find("dpkg-query -W -f=${Status} dpkg-dev"), std::string::npos) << calls;
  for (const char* test_only : {" libgtest-dev", " strace", " python3-numpy", " libczmq-dev"})
    EXPECT_EQ(calls.find(test_only), std::string::npos) << test_only << " asked for a package build:\n" << calls;
  EXPECT_EQ(calls.find("npm"), std::string::npos) << calls;
  EXPECT_EQ(r.out.find("npm ci"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace bodyd::test
