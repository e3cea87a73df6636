// Every built program on a CPU without AVX2 and FMA (docs/install.md, "The CPU"): x86-64 builds
// use them, and a program started on a CPU that lacks them must say so and exit 2 rather than die
// of SIGILL. The older CPUs are QEMU's user-mode emulation of real models (qemu-x86_64 -cpu,
// Debian's qemu-user, installed by scripts/setup); -cpu max shows that the same emulator runs the
// same program to the end when the CPU has what it needs.
#include "../test_paths.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;

const fs::path kQemu = "/usr/bin/qemu-x86_64";

// Skips unless this build carries the check and QEMU can run its programs.
void require_emulator() {
#if !defined(BODYD_CPU_NEEDS_AVX2_FMA)
  GTEST_SKIP() << "this build needs no more than the CPU it was built on (BODYD_NATIVE, or not x86-64)";
#elif defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "ASan's shadow memory does not fit QEMU's user-mode address space";
#else
  if (!fs::exists(kQemu)) GTEST_SKIP() << "qemu-x86_64 is not installed (Debian's qemu-user; scripts/setup installs it)";
#endif
}

// The programs and tools of the build (build/bin): everything that links bodyd_base.
std::vector<fs::path> programs() {
  std::vector<fs::path> out;
  for (const fs::directory_entry& e : fs::directory_iterator(fs::path(BODYD_BIN_DIR)))
    if (e.is_regular_file() && ::access(e.path().c_str(), X_OK) == 0) out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

RunResult run_on(const std::string& cpu, const std::vector<std::string>& args, const fs::path& dir) {
  std::vector<std::string> argv = {kQemu.string(), "-cpu", cpu};
  argv.insert(argv.end(), args.begin(), args.end());
  return run(argv, {.output_dir = dir, .name = "qemu"}, 120000);
}

TEST(Cpu, TheDaemonRunsOnAnEmulatedCpuThatHasAvx2AndFma) {
  require_emulator();
  if (IsSkipped()) return;
  const TempDir dir("bodyd-cpu");
  const RunResult r = run_on("max", {(fs::path(BODYD_BIN_DIR) / "bodyd").string(), "--version"}, dir.path);
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_EQ(r.err.find("needs a CPU"), std::string::npos) << r.err;
}

// Sandy Bridge (2011) has AVX but neither AVX2 nor FMA; Nehalem (2008) not even AVX, so there any
// VEX-encoded instruction before the check would already be fatal.
TEST(Cpu, EveryProgramOnAnOlderCpuSaysWhatItNeedsAndExits2) {
  require_emulator();
  if (IsSkipped()) return;
  const TempDir dir("bodyd-cpu");
  const std::vector<fs::path> all = programs();
  ASSERT_GE(all.size(), 10u) << "expected the build's programs in " << BODYD_BIN_DIR;
  for (const char* cpu : {"SandyBridge", "Nehalem"}) {
    for (const fs::path& program : all) {
      SCOPED_TRACE(std::string(cpu) + " " + program.filename().string());
      const RunResult r = run_on(cpu, {program.string(), "--help"}, dir.path);
      EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
      EXPECT_NE(r.err.find("bodyd: this build needs a CPU with AVX2 and FMA"), std::string::npos) << r.err;
      EXPECT_NE(r.err.find("lacks both"), std::string::npos) << r.err;
      EXPECT_NE(r.err.find("-DBODYD_NATIVE=ON"), std::string::npos) << r.err;
      EXPECT_TRUE(r.out.empty()) << "the program ran before the check: " << r.out;
    }
  }
}

}  // namespace
}  // namespace bodyd::test
