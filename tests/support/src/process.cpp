#include "bodyd/test/process.h"

#include "bodyd/test/files.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace bodyd::test {

Process::Process(const std::vector<std::string>& args, const ProcessOptions& options)
    : destroy_grace_ms_(options.destroy_grace_ms) {
  if (args.empty()) throw std::logic_error("Process: no command");
  if (options.output_dir.empty() && (options.stdout_path.empty() || options.stderr_path.empty()))
    throw std::logic_error("Process: output_dir, or both stdout_path and stderr_path, are required");
  out_path_ = options.stdout_path.empty() ? options.output_dir / (options.name + ".stdout") : options.stdout_path;
  err_path_ = options.stderr_path.empty() ? options.output_dir / (options.name + ".stderr") : options.stderr_path;
  std::map<std::string, std::string> env = options.env;
  // A bodyd child keeps its calibration in $XDG_STATE_HOME/bodyd (docs/daemon.md, "Device
  // mounting"): never the user's own, one folder per test's output folder.
  if (!env.count("XDG_STATE_HOME")) {
    const std::filesystem::path place = options.output_dir.empty() ? err_path_.parent_path() : options.output_dir;
    env["XDG_STATE_HOME"] = (place.empty() || place == "/dev" ? std::filesystem::path("/nonexistent") : place) / "xdg-state";
  }
  std::vector<std::string> env_strings;
  for (char** e = environ; *e; ++e) {
    const std::string entry = *e;
    if (!env.count(entry.substr(0, entry.find('=')))) env_strings.push_back(entry);
  }
  for (const auto& [k, v] : env)
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
  if (!options.cwd.empty()) posix_spawn_file_actions_addchdir_np(&actions, options.cwd.c_str());
  const int rc = options.search_path ? posix_spawnp(&pid_, argv[0], &actions, nullptr, argv.data(), envp.data())
                                     : posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) throw std::runtime_error("cannot start " + args[0] + ": " + std::strerror(rc));
}

Process::~Process() {
  if (exit_code_) return;
  if (destroy_grace_ms_ > 0 && terminate(destroy_grace_ms_)) return;
  ::kill(pid_, SIGKILL);
  int status = 0;
  ::waitpid(pid_, &status, 0);
}

void Process::signal(int sig) const {
  if (!exit_code_) ::kill(pid_, sig);
}

std::optional<int> Process::wait(int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (!exit_code_) {
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      break;
    }
    if (std::chrono::steady_clock::now() > deadline) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return exit_code_;
}

std::optional<int> Process::terminate(int timeout_ms) {
  signal(SIGTERM);
  return wait(timeout_ms);
}

std::string Process::out() const { return read_file(out_path_); }
std::string Process::err() const { return read_file(err_path_); }

RunResult run(const std::vector<std::string>& args, const ProcessOptions& options, int timeout_ms) {
  Process p(args, options);
  RunResult r;
  const auto code = p.wait(timeout_ms);
  r.exit_code = code ? *code : -1;
  r.out = p.out();
  r.err = p.err();
  return r;
}

ShellResult shell(const std::string& command) {
  ShellResult r;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return r;
  char buffer[4096];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) r.out.append(buffer, n);
  const int status = ::pclose(pipe);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::optional<std::string> wait_for_file(const std::filesystem::path& file, int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    std::string text = read_file(file);
    if (!text.empty() && text.back() == '\n') return text;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return std::nullopt;
}

}  // namespace bodyd::test
