// bodyd: the daemon's executable (docs/daemon.md). Everything but signal handling and the
// command line lives in the bodyd_daemon library.
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/daemon.h"
#include "bodyd/daemon/endpoint.h"
#include "bodyd/daemon/reconstructors.h"
#include "bodyd/drivers/device_list.h"

#include <nlohmann/json.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <csignal>
#include <cstdio>
#include <iostream>

namespace {

volatile std::sig_atomic_t g_stop_signal = 0;

// Only sets the flag: Daemon::run() polls it (async-signal-safe).
extern "C" void on_stop_signal(int) { g_stop_signal = 1; }

void install_signal_handlers() {
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
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
      if (std::string e = generate_curve_keys(cli.gen_keys_dir, keys); !e.empty()) {
        std::cerr << "bodyd: " << e << "\n";
        return 1;
      }
      std::cout << "wrote " << cli.gen_keys_dir << "/server.secret (keep private; bodyd --curve-secret-key)\n"
                << "wrote " << cli.gen_keys_dir << "/server.public (give to clients: ZMQ_CURVE_SERVERKEY)\n"
                << "public key: " << keys.public_key << "\n";
      return 0;
    }
    case CliResult::Action::ListDevices: std::cout << bodyd::drivers::list_devices_text(); return 0;
    case CliResult::Action::Run: break;
  }

  auto logger = spdlog::stderr_color_mt("bodyd");
  logger->set_pattern("%Y-%m-%d %H:%M:%S.%e bodyd %^%l%$: %v");
  spdlog::set_default_logger(logger);
  spdlog::set_level(spdlog::level::from_str(config.log_level));
  install_signal_handlers();

  const std::filesystem::path skeleton =
      config.skeleton_path.empty() ? bundled_skeleton_path() : std::filesystem::path(config.skeleton_path);
  Daemon daemon(config, make_default_factory(skeleton));
  if (std::string e = daemon.start(); !e.empty()) {
    spdlog::critical("{}", e);
    return 1;
  }
  return daemon.run(&g_stop_signal);
}
