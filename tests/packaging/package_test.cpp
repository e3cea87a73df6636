// The Debian package (make package, docs/install.md): its name, control fields, contents, and
// the packaged bodyd running from a scratch root (dpkg -x) on its own bundled files. One cpack
// run serves every test of the suite.
#include "../test_paths.h"
#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>

#include <fstream>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;

const fs::path kBuildDir = BODYD_BUILD_DIR;
const fs::path kCpack = BODYD_CPACK_COMMAND;

std::string trim(std::string s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  return s;
}

class DebianPackage : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    for (const char* tool : {"/usr/bin/dpkg-deb", "/usr/bin/dpkg-shlibdeps", "/usr/bin/dpkg"})
      if (!fs::exists(tool)) {
        skip_ = std::string(tool) + " is not installed (package dpkg-dev; scripts/setup installs it)";
        return;
      }
    scratch_ = new TempDir("bodyd-package");
    const RunResult arch = run({"/usr/bin/dpkg", "--print-architecture"}, {.output_dir = scratch_->path, .name = "arch"});
    arch_ = trim(arch.out);
    // -B: the package and cpack's staging tree go to the scratch directory, not the build tree.
    const RunResult r = run({kCpack.string(), "-G", "DEB", "--config", (kBuildDir / "CPackConfig.cmake").string(), "-B",
                             (scratch_->path / "out").string()},
                            {.cwd = scratch_->path, .output_dir = scratch_->path, .name = "cpack"}, 300000);
    log_ = r.out + r.err;
    deb_ = scratch_->path / "out" / ("bodyd_" + std::string(BODYD_VERSION) + "_" + arch_ + ".deb");
    ok_ = r.exit_code == 0;
  }
  static void TearDownTestSuite() {
    delete scratch_;
    scratch_ = nullptr;
  }
  void SetUp() override {
    if (!skip_.empty()) GTEST_SKIP() << skip_;
    ASSERT_TRUE(ok_) << "cpack failed:\n" << log_;
    ASSERT_TRUE(fs::is_regular_file(deb_)) << deb_ << " was not made; cpack said:\n" << log_;
  }
  static std::string field(const std::string& name) {
    return trim(run({"/usr/bin/dpkg-deb", "--field", deb_.string(), name}, {.output_dir = scratch_->path, .name = "field"}).out);
  }

  static inline TempDir* scratch_ = nullptr;
  static inline fs::path deb_;
  static inline std::string arch_, log_, skip_;
  static inline bool ok_ = false;
};

TEST_F(DebianPackage, IsNamedAndDescribedForApt) {
  EXPECT_EQ(field("Package"), "bodyd");
  EXPECT_EQ(field("Version"), BODYD_VERSION);
  EXPECT_EQ(field("Architecture"), arch_);
  EXPECT_FALSE(field("Maintainer").empty());
  EXPECT_FALSE(field("Description").empty());
  // Computed by dpkg-shlibdeps from the programs' shared libraries.
  const std::string depends = field("Depends");
  for (const char* lib : {"libc6", "libstdc++6", "libzmq5", "libsystemd0"})
    EXPECT_NE(depends.find(lib), std::string::npos) << lib << " missing from Depends: " << depends;
  EXPECT_NE(field("Recommends").find("libjs-three"), std::string::npos);
}

TEST_F(DebianPackage, HoldsProgramsDataUnitUdevRuleAndClientLibrary) {
  const std::string list =
      run({"/usr/bin/dpkg-deb", "--contents", deb_.string()}, {.output_dir = scratch_->path, .name = "contents"}).out;
  for (const char* path : {"./usr/bin/bodyd", "./usr/bin/bodyd-ctl", "./usr/bin/bodyd-sub",
                           "./usr/bin/bodyd-viewer-bridge", "./usr/share/bodyd/models/bodyd-default.safetensors",
                           "./usr/share/bodyd/data/demo/walk.csv", "./usr/share/bodyd/viewer/index.html",
                           "./usr/lib/systemd/user/bodyd.service", "./usr/lib/udev/rules.d/70-bodyd.rules",
                           "./usr/include/bodyd_client.h", "libbodyd_client.so", "pkgconfig/bodyd-client.pc",
                           "./usr/share/doc/bodyd/docs/install.md"}) {
    // dpkg-deb --contents ends a file's line with its path, a symlink's with "PATH -> TARGET".
    const bool listed = list.find(std::string(path) + "\n") != std::string::npos ||
                        list.find(std::string(path) + " -> ") != std::string::npos;
    EXPECT_TRUE(listed) << path << " not in the package:\n" << list.substr(0, 4000);
  }
  // A test tool is not shipped (issue 20 item 8).
  EXPECT_EQ(list.find("bodyd-testpub"), std::string::npos) << "the package ships the test tool bodyd-testpub";
  // Nothing of the build machine: no source or build paths, nothing outside /usr.
  EXPECT_EQ(list.find(source_dir().string()), std::string::npos);
  std::istringstream lines(list);
  std::string line;
  while (std::getline(lines, line)) {
    const auto dot = line.find(" ./");
    ASSERT_NE(dot, std::string::npos) << line;
    const std::string path = line.substr(dot + 1);
    EXPECT_TRUE(path.rfind("./usr/", 0) == 0 || path.rfind("./ ", 0) == 0 || path == "./usr/" || path == "./") << line;
  }
}

// Unpacked into a scratch root, the package's bodyd finds its model and recording next to
// itself (ROOT/usr/share/bodyd), and its unit starts /usr/bin/bodyd.
TEST_F(DebianPackage, UnpackedBodydRunsOnItsOwnFiles) {
  const fs::path root = scratch_->path / "root";
  const RunResult x = run({"/usr/bin/dpkg", "-x", deb_.string(), root.string()}, {.output_dir = scratch_->path, .name = "x"});
  ASSERT_EQ(x.exit_code, 0) << x.err;
  EXPECT_NE(read_file(root / "usr/lib/systemd/user/bodyd.service").find("ExecStart=/usr/bin/bodyd --user-config\n"),
            std::string::npos);
  TempDir dir("bodyd-unpacked");
  const RunResult r = run({(root / "usr/bin/bodyd").string(), "--exit-at-end", "--fast", "--pub",
                           "ipc://" + (dir.path / "pose").string(), "--control", "none"},
                          {.env = {{"XDG_DATA_HOME", (dir.path / "xdg").string()}}, .cwd = dir.path,
                           .output_dir = dir.path, .name = "bodyd"},
                          120000);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find((root / "usr/share/bodyd/models/bodyd-default.safetensors").string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find((root / "usr/share/bodyd/data/demo/walk.csv").string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("every source has finished; 732 poses published"), std::string::npos) << r.err;
  // bodyd-ctl runs too (its usage).
  const RunResult ctl = run({(root / "usr/bin/bodyd-ctl").string(), "--help"}, {.output_dir = dir.path, .name = "ctl"});
  EXPECT_EQ(ctl.exit_code, 0) << ctl.err;
  EXPECT_NE(ctl.out.find("calibrate"), std::string::npos);
}

// apt remove leaves no dangling per-user enable link (issue 20 item 8): the package's postrm,
// run as dpkg runs it after removing the files ("remove"), deletes a user's
// default.target.wants/bodyd.service link to the removed unit and nothing else. The passwd
// database is a fake getent on PATH naming two scratch homes.
TEST_F(DebianPackage, PostrmRemovesDanglingUserEnableLinksOnly) {
  if (fs::exists("/usr/lib/systemd/user/bodyd.service"))
    GTEST_SKIP() << "bodyd is installed on this machine, so its unit's links do not dangle here";
  const fs::path control = scratch_->path / "control";
  const RunResult e = run({"/usr/bin/dpkg-deb", "-e", deb_.string(), control.string()},
                          {.output_dir = scratch_->path, .name = "e"});
  ASSERT_EQ(e.exit_code, 0) << e.err;
  const fs::path postrm = control / "postrm";
  ASSERT_TRUE(fs::is_regular_file(postrm)) << "the package has no postrm";
  EXPECT_NE(fs::status(postrm).permissions() & fs::perms::owner_exec, fs::perms::none);

  TempDir dir("bodyd-postrm");
  const fs::path alice = dir.path / "alice", bob = dir.path / "bob", bin = dir.path / "bin";
  const fs::path wants = alice / ".config/systemd/user/default.target.wants";
  const fs::path bob_wants = bob / ".config/systemd/user/default.target.wants";
  fs::create_directories(wants);
  fs::create_directories(bob_wants);
  fs::create_directories(bin);
  fs::create_symlink("/usr/lib/systemd/user/bodyd.service", wants / "bodyd.service");  // dangles here
  fs::create_symlink("/usr/lib/systemd/user/other.service", wants / "other.service");  // not ours
  fs::create_symlink(alice / "own-bodyd.service", bob_wants / "bodyd.service");          // the user's own unit
  {
    std::ofstream getent(bin / "getent");
    getent << "#!/bin/sh\nprintf 'alice:x:1000:1000::" << alice.string() << ":/bin/sh\\nbob:x:1001:1001::"
           << bob.string() << ":/bin/sh\\nnobody:x:65534:65534::/nonexistent:/bin/false\\n'\n";
  }
  fs::permissions(bin / "getent", fs::perms::owner_all);
  const RunResult r = run({"/bin/sh", postrm.string(), "remove"},
                          {.env = {{"PATH", bin.string() + ":/usr/bin:/bin"}}, .output_dir = dir.path, .name = "postrm"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_FALSE(fs::is_symlink(wants / "bodyd.service")) << "the dangling enable link is still there";
  EXPECT_TRUE(fs::is_symlink(wants / "other.service"));
  EXPECT_TRUE(fs::is_symlink(bob_wants / "bodyd.service"));
  EXPECT_NE(r.out.find("removed " + (wants / "bodyd.service").string()), std::string::npos) << r.out;
  // An upgrade keeps every link.
  fs::create_symlink("/usr/lib/systemd/user/bodyd.service", wants / "bodyd.service");
  const RunResult up = run({"/bin/sh", postrm.string(), "upgrade", "0.1.0"},
                           {.env = {{"PATH", bin.string() + ":/usr/bin:/bin"}}, .output_dir = dir.path, .name = "upgrade"});
  EXPECT_EQ(up.exit_code, 0);
  EXPECT_TRUE(fs::is_symlink(wants / "bodyd.service"));
}

}  // namespace
}  // namespace bodyd::test
