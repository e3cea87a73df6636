// The CPU check every bodyd program runs before anything else (docs/install.md, "The CPU").
//
// x86-64 builds are compiled with AVX2 and FMA (CMakeLists.txt), so on a CPU without them a
// program would die at its first such instruction with a bare "Illegal instruction". This file
// alone is compiled without them (base/CMakeLists.txt) and runs, as a constructor ahead of every
// C++ static initialiser, a check that says what is missing and what to do instead.
// BODYD_CPU_NEEDS is the build's requirement ("avx2,fma"); it is not defined for
// BODYD_NATIVE builds, which are made for the machine they run on.
#include <unistd.h>

#include <cstring>

extern "C" {
// Referenced by the linker (-u, base/CMakeLists.txt) so that a static link keeps this file.
extern const char bodyd_cpu_check[];
const char bodyd_cpu_check[] = "bodyd cpu check";
}

#if defined(BODYD_CPU_NEEDS_AVX2_FMA) && (defined(__x86_64__) || defined(__i386__))
namespace {

void say(const char* text) {
  // write(2): no stdio or iostream buffers exist yet, and this must not allocate.
  const ssize_t ignored = ::write(STDERR_FILENO, text, std::strlen(text));
  (void)ignored;
}

__attribute__((constructor(101))) void check_cpu() {
  __builtin_cpu_init();
  const bool avx2 = __builtin_cpu_supports("avx2") != 0;
  const bool fma = __builtin_cpu_supports("fma") != 0;
  if (avx2 && fma) return;
  say("bodyd: this build needs a CPU with AVX2 and FMA (x86-64-v3: Intel since Haswell, 2013; AMD since "
      "Excavator, 2015), and this CPU lacks ");
  say(!avx2 && !fma ? "both" : !avx2 ? "AVX2" : "FMA");
  say(". Build bodyd from source on this machine with `cmake -S . -B build -DBODYD_NATIVE=ON` "
      "(docs/install.md, \"The CPU\").\n");
  ::_exit(2);  // as for a bad config: the unit's RestartPreventExitStatus=2 stops systemd retrying
}

}  // namespace
#endif
