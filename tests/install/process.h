// Child processes for the install, package and service tests: argv, extra environment
// variables, a working directory, stdout and stderr captured in files.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace bodyd::test {

inline std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Tests fill ProcessOptions with designated initializers ({.env = ..., .output_dir = ...}),
// leaving the other members at their defaults on purpose; GCC 12 would warn for each.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

struct ProcessOptions {
  std::map<std::string, std::string> env;  // set (or, with value "\x01unset", removed) in the child
  std::filesystem::path cwd;               // empty: the test's
  std::filesystem::path output_dir;        // where stdout/stderr files go (required)
  std::string name = "child";              // file name stem
};

inline constexpr const char* kUnset = "\x01unset";

class Process {
 public:
  Process(const std::vector<std::string>& args, const ProcessOptions& options) {
    if (options.output_dir.empty()) throw std::logic_error("Process: output_dir is required");
    out_path_ = options.output_dir / (options.name + ".stdout");
    err_path_ = options.output_dir / (options.name + ".stderr");
    std::vector<std::string> env_strings;
    for (char** e = environ; *e; ++e) {
      const std::string entry = *e;
      const std::string key = entry.substr(0, entry.find('='));
      if (!options.env.count(key)) env_strings.push_back(entry);
    }
    for (const auto& [k, v] : options.env)
      if (v != kUnset) env_strings.push_back(k + "=" + v);
    std::vector<char*> envp;
    for (auto& e : env_strings) envp.push_back(e.data());
    envp.push_back(nullptr);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);

    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 1, out_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 2, err_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 29))
    if (!options.cwd.empty()) posix_spawn_file_actions_addchdir_np(&actions, options.cwd.c_str());
#endif
    const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) throw std::runtime_error("cannot start " + args[0] + ": " + std::strerror(rc));
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;
  ~Process() {
    if (!exit_code_) {
      kill(pid_, SIGKILL);
      int status = 0;
      waitpid(pid_, &status, 0);
    }
  }
  void signal(int sig) const {
    if (!exit_code_) kill(pid_, sig);
  }
  // Exit code (128 + signal when killed), or nullopt while still running after timeout_ms.
  std::optional<int> wait(int timeout_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (!exit_code_) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        break;
      }
      if (std::chrono::steady_clock::now() > deadline) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return exit_code_;
  }
  std::string out() const { return read_file(out_path_); }
  std::string err() const { return read_file(err_path_); }
  std::string log() const { return "--- stdout:\n" + out() + "--- stderr:\n" + err(); }

 private:
  pid_t pid_ = -1;
  std::optional<int> exit_code_;
  std::filesystem::path out_path_, err_path_;
};

struct RunResult {
  int exit_code = -1;  // -1: did not finish in time (killed)
  std::string out, err;
};

// Runs a command to completion (killed after timeout_ms).
inline RunResult run(const std::vector<std::string>& args, ProcessOptions options, int timeout_ms = 60000) {
  Process p(args, options);
  RunResult r;
  const auto code = p.wait(timeout_ms);
  r.exit_code = code ? *code : -1;
  r.out = p.out();
  r.err = p.err();
  return r;
}

// A fresh temporary directory, removed at destruction.
struct ScratchDir {
  std::filesystem::path path;
  explicit ScratchDir(const char* stem = "bodyd-test") {
    std::string tmpl = (std::filesystem::temp_directory_path() / (std::string(stem) + "-XXXXXX")).string();
    if (!mkdtemp(tmpl.data())) throw std::runtime_error("mkdtemp failed");
    path = tmpl;
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

// Waits until `file` exists and holds a complete line; its text, or nullopt after timeout_ms.
inline std::optional<std::string> wait_for_file(const std::filesystem::path& file, int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    std::string text = read_file(file);
    if (!text.empty() && text.back() == '\n') return text;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return std::nullopt;
}

}  // namespace bodyd::test
