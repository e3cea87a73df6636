// Child processes for tests: argv, extra or removed environment variables, a working
// directory, stdin from /dev/null, stdout and stderr in files (or dropped).
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace bodyd::test {

// Tests fill ProcessOptions with designated initializers ({.env = ..., .output_dir = ...}),
// leaving the other members at their defaults on purpose; GCC 12 would warn for each.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

// As a value in ProcessOptions::env: the variable is removed in the child.
inline constexpr const char* kUnset = "\x01unset";

struct ProcessOptions {
  // Set (or, with value kUnset, removed) in the child. XDG_STATE_HOME, unless named here, is
  // <output_dir>/xdg-state (or beside stderr_path), so a bodyd child never reads or writes the
  // user's calibration (~/.local/state/bodyd/mounting.json) and children of one test share one.
  std::map<std::string, std::string> env;
  std::filesystem::path cwd;               // empty: the test's
  std::filesystem::path output_dir;        // stdout and stderr go to <output_dir>/<name>.stdout, .stderr
  std::string name = "child";              // file name stem
  std::filesystem::path stdout_path;       // instead of output_dir's (e.g. "/dev/null")
  std::filesystem::path stderr_path;       // instead of output_dir's
  bool search_path = false;                // args[0] looked up on PATH (posix_spawnp)
  int destroy_grace_ms = 0;                // at destruction: SIGTERM and this long, then SIGKILL
};

class Process {
 public:
  // Starts args[0]; throws std::runtime_error when it cannot (or no output place is given).
  Process(const std::vector<std::string>& args, const ProcessOptions& options);
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;
  // Still running: SIGTERM and destroy_grace_ms to exit, then SIGKILL; always reaped.
  ~Process();

  [[nodiscard]] pid_t pid() const { return pid_; }
  [[nodiscard]] bool running() const { return !exit_code_.has_value(); }
  void signal(int sig) const;
  // Exit code (128 + signal when killed), or nullopt while still running after timeout_ms.
  std::optional<int> wait(int timeout_ms);
  // SIGTERM, then wait(timeout_ms).
  std::optional<int> terminate(int timeout_ms);

  [[nodiscard]] const std::filesystem::path& stdout_path() const { return out_path_; }
  [[nodiscard]] const std::filesystem::path& stderr_path() const { return err_path_; }
  [[nodiscard]] std::string out() const;
  [[nodiscard]] std::string err() const;
  [[nodiscard]] std::string log() const { return "--- stdout:\n" + out() + "--- stderr:\n" + err(); }

 private:
  pid_t pid_ = -1;
  int destroy_grace_ms_ = 0;
  std::optional<int> exit_code_;
  std::filesystem::path out_path_, err_path_;
};

struct RunResult {
  int exit_code = -1;  // -1: did not finish in time (killed)
  std::string out, err;
};

// Runs a command to completion (killed after timeout_ms).
RunResult run(const std::vector<std::string>& args, const ProcessOptions& options, int timeout_ms = 60000);

// A shell command's exit status (-1 when it did not exit normally) and standard output.
struct ShellResult {
  int status = -1;
  std::string out;
};
// Runs `command` with /bin/sh (popen) to completion; add 2>&1 to the command for stderr too.
ShellResult shell(const std::string& command);

// Waits until `file` exists and holds a complete line; its text, or nullopt after timeout_ms.
std::optional<std::string> wait_for_file(const std::filesystem::path& file, int timeout_ms);

}  // namespace bodyd::test
