// bodyd: the daemon's executable (docs/daemon.md). Everything but signal handling and the
// command line lives in the bodyd_daemon library.
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/daemon.h"
#include "bodyd/io/zmq/endpoint.h"
#include "bodyd/daemon/reconstructors.h"
#include "bodyd/daemon/service.h"
#include "bodyd/io/devices/device_list.h"

#include <nlohmann/json.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/sinks/systemd_sink.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <condition_variable>
#include <functional>
#include <csignal>
#include <mutex>
#include <thread>
#include <cstdio>
#include <sys/resource.h>

#include <algorithm>
#include <iostream>

namespace {

volatile std::sig_atomic_t g_stop_signal = 0;

// Only records the signal: Daemon::run() polls the flag (async-signal-safe).
extern "C" void on_stop_signal(int signal_number) { g_stop_signal = signal_number; }

// docs/daemon.md, "Signals": INT, TERM, HUP (the terminal closed) and QUIT shut down cleanly
// (the recording flushed, "stopped" logged, exit 0); USR1, USR2, ALRM, PIPE are ignored, and so
// is XFSZ, so that a file over the size limit is a write error that is reported.
void install_signal_handlers() {
  struct sigaction stop {};
  stop.sa_handler = on_stop_signal;
  sigemptyset(&stop.sa_mask);
  for (int s : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) sigaction(s, &stop, nullptr);
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigemptyset(&ignore.sa_mask);
  for (int s : {SIGUSR1, SIGUSR2, SIGALRM, SIGPIPE, SIGXFSZ}) sigaction(s, &ignore, nullptr);
}

// Under systemd with WatchdogSec=: pings the watchdog while the daemon is alive (its
// reconstruction loop keeps turning), so a hung bodyd is restarted.
class WatchdogThread {
 public:
  // `progress` returns a count that grows while the daemon is alive.
  WatchdogThread(const bodyd::daemon::ServiceNotifier& notifier, std::function<std::uint64_t()> progress) {
    const auto interval = notifier.watchdog_ping_interval();
    if (interval.count() <= 0) return;
    thread_ = std::thread([this, &notifier, progress = std::move(progress), interval] {
      std::uint64_t last = progress();
      bool first = true;
      std::unique_lock lock(mutex_);
      while (!stop_) {
        const std::uint64_t now = progress();
        // The loop turns at least every 20 ms (its queue wait), so in a ping interval it always
        // advances unless it hangs.
        if (first || now != last) notifier.watchdog();
        first = false;
        last = now;
        wake_.wait_for(lock, interval, [this] { return stop_; });
      }
    });
  }
  ~WatchdogThread() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

 private:
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace

namespace {

// The soft descriptor limit raised to the hard one (at most kWantedDescriptors): desktop sessions
// and services start with 1,024 under a hard limit in the hundreds of thousands, and libzmq 4.3's
// ipc:// listener aborts the process when accept() meets EMFILE (docs/reliability.md), so the
// servers' caps are a quarter of a generous limit. A hard limit as low as the soft one stays.
void raise_descriptor_limit() {
  constexpr rlim_t kWantedDescriptors = 65536;
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur >= kWantedDescriptors) return;
  const rlim_t before = limit.rlim_cur;
  limit.rlim_cur = limit.rlim_max == RLIM_INFINITY ? kWantedDescriptors : std::min(limit.rlim_max, kWantedDescriptors);
  if (limit.rlim_cur > before && ::setrlimit(RLIMIT_NOFILE, &limit) == 0)
    spdlog::debug("file descriptor limit raised from {} to {}", static_cast<unsigned long long>(before),
                  static_cast<unsigned long long>(limit.rlim_cur));
}

}  // namespace

int main(int argc, char** argv) {
  using namespace bodyd::daemon;
  DaemonConfig config;
  const CliResult cli = parse_command_line(argc, argv, config);
  switch (cli.action) {
    case CliResult::Action::Exit: return cli.exit_code;
    case CliResult::Action::PrintConfig: std::cout << config_to_json(config).dump(2) << "\n"; return 0;
    case CliResult::Action::GenKeys: {
      CurveKeyPair keys;
      if (std::string e = generate_curve_keys(cli.gen_keys_dir, keys, cli.gen_keys_name); !e.empty()) {
        std::cerr << "bodyd: " << e << "\n";
        return 1;
      }
      const std::string base = cli.gen_keys_dir + "/" + cli.gen_keys_name;
      if (cli.gen_keys_name == "server")
        std::cout << "wrote " << base << ".secret (keep private; bodyd --curve-secret-key)\n"
                  << "wrote " << base << ".public (give to clients: ZMQ_CURVE_SERVERKEY)\n";
      else
        std::cout << "wrote " << base << ".secret (give to this client only: its ZMQ_CURVE_SECRETKEY; "
                  << "bodyd-ctl --curve-client-key)\n"
                  << "wrote " << base << ".public (copy into bodyd's --curve-allow directory)\n";
      std::cout << "public key: " << keys.public_key << "\n";
      return 0;
    }
    case CliResult::Action::ListDevices: {
      // The bundled recording, named as the thing to try when no tracker is found.
      const std::filesystem::path demo = bundled_recording_path();
      std::cout << bodyd::drivers::list_devices_text(std::filesystem::is_regular_file(demo) ? demo.string() : std::string());
      return 0;
    }
    case CliResult::Action::Run: break;
  }

  if (stderr_is_journal()) {
    // The journal keeps time, program name and priority itself.
    auto logger = std::make_shared<spdlog::logger>("bodyd", std::make_shared<spdlog::sinks::systemd_sink_mt>("bodyd"));
    logger->set_pattern("%v");
    spdlog::set_default_logger(logger);
  } else {
    auto logger = spdlog::stderr_color_mt("bodyd");
    logger->set_pattern("%Y-%m-%d %H:%M:%S.%e bodyd %^%l%$: %v");
    spdlog::set_default_logger(logger);
  }
  spdlog::set_level(spdlog::level::from_str(config.log_level));
  for (const auto& note : cli.notes) spdlog::info("{}", note);
  raise_descriptor_limit();
  install_signal_handlers();
  const ServiceNotifier notifier;

  const std::filesystem::path skeleton =
      config.skeleton_path.empty() ? bundled_skeleton_path() : std::filesystem::path(config.skeleton_path);
  bodyd::ReconstructorOptions reconstructor_options;
  reconstructor_options.filter = config.filter;
  reconstructor_options.body_filter = config.body_filter;
  Daemon daemon(config, make_default_factory(skeleton, reconstructor_options));
  if (std::string e = daemon.start(); !e.empty()) {
    spdlog::critical("{}", e);
    notifier.status("failed to start: " + e);
    return 1;
  }
  notifier.ready("publishing poses on " + daemon.pub_endpoint() +
                 (daemon.control_endpoint().empty() ? "" : ", control " + daemon.control_endpoint()));
  int code = 0;
  {
    const WatchdogThread watchdog(notifier, [&daemon] { return daemon.loop_iterations(); });
    code = daemon.run(&g_stop_signal);
  }
  notifier.stopping();
  return code;
}
