// bodyd-ctl: the command-line client of bodyd's control socket (docs/ctl.md, docs/control.md).
//
//   bodyd-ctl status [--json]
//   bodyd-ctl calibrate --head-height-m 1.62 | --height-m 1.80 | --from-head | --pose [--in SECONDS]
//   bodyd-ctl recenter        (reset: its old name)
//   bodyd-ctl reload-model [PATH]
//   bodyd-ctl shutdown
//   bodyd-ctl skeleton
//
// One request through the C++ client (client/include/bodyd/client/client.h), one reply, with a
// timeout: a daemon that does not answer is reported with the endpoint tried and how to start
// one, never waited for forever.
// Exit codes: 0 done; 1 bodyd answered with an error; 2 bad command line; 3 no answer.
#include "bodyd/client/client.h"
#include "bodyd/client/curve_keys.h"
#include "bodyd/motion/tracker.h"
#include "bodyd/paths/data_files.h"

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr int kExitError = 1, kExitUsage = 2, kExitNoAnswer = 3;
constexpr const char* kDefaultControl = "ipc:///tmp/bodyd/control";

std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Where to send requests, and why there (for the message when nobody answers).
struct Target {
  std::string endpoint;
  std::string from;
};

// --control, else --endpoints-file, else the "control" key of the user's config file (what the
// systemd unit runs with), else bodyd's default.
std::optional<Target> choose_target(const std::string& control_flag, const std::string& endpoints_file,
                                    std::string& error) {
  if (!control_flag.empty()) return Target{control_flag, "--control"};
  if (!endpoints_file.empty()) {
    const json j = json::parse(read_text(endpoints_file), nullptr, false);
    if (j.is_discarded() || !j.is_object() || !j.contains("control") || !j["control"].is_string() ||
        j["control"].get<std::string>().empty()) {
      error = endpoints_file + ": not a bodyd endpoints file with a \"control\" endpoint (bodyd --endpoints-file)";
      return std::nullopt;
    }
    return Target{j["control"].get<std::string>(), "--endpoints-file " + endpoints_file};
  }
  const fs::path config = bodyd::paths::user_config_file();
  std::error_code ec;
  if (!config.empty() && fs::exists(config, ec)) {
    const json j = json::parse(read_text(config), nullptr, /*allow_exceptions=*/false, /*ignore_comments=*/true);
    if (!j.is_discarded() && j.is_object() && j.contains("control") && j["control"].is_string()) {
      const std::string c = j["control"].get<std::string>();
      if (c == "none" || c.empty()) {
        error = config.string() + " sets \"control\": \"" + c + "\": that bodyd has no control socket";
        return std::nullopt;
      }
      return Target{c, "\"control\" in " + config.string()};
    }
  }
  return Target{kDefaultControl, "bodyd's default"};
}

// The client's CURVE keys; the client makes a fresh pair when client_secret is empty.
struct Curve {
  std::string server_public, client_secret;
};

std::optional<Curve> load_curve(const std::string& server_key_file, const std::string& client_key_file,
                                std::string& error) {
  if (server_key_file.empty()) {
    if (!client_key_file.empty()) error = "--curve-client-key needs --curve-server-key (the server's public key file)";
    return std::nullopt;
  }
  Curve c;
  if (std::string e = bodyd::client::read_curve_key_file(server_key_file, c.server_public); !e.empty()) {
    error = e;
    return std::nullopt;
  }
  // No key of our own: the client makes a fresh pair (enough when bodyd has no --curve-allow list).
  if (client_key_file.empty()) return c;
  if (std::string e = bodyd::client::read_curve_key_file(client_key_file, c.client_secret); !e.empty()) {
    error = e;
    return std::nullopt;
  }
  if (bodyd::client::curve_public_from_secret(c.client_secret).empty()) {
    error = client_key_file + ": not a CURVE secret key (bodyd --gen-keys DIR --client NAME writes DIR/NAME.secret)";
    return std::nullopt;
  }
  return c;
}

std::string no_answer_message(const Target& target, double timeout_s, bool curve) {
  std::string m = fmt::format("bodyd-ctl: no answer from bodyd on {} ({}) within {:g} s.\n", target.endpoint,
                              target.from, timeout_s);
  if (target.endpoint.rfind("ipc://", 0) == 0) {
    const fs::path socket = target.endpoint.substr(6);
    std::error_code ec;
    if (!fs::exists(socket, ec)) m += fmt::format("  Nothing listens there: {} does not exist.\n", socket.string());
  }
  m += "  Is bodyd running? Start it with `systemctl --user start bodyd` (the installed service) or run `bodyd`;\n"
       "  `systemctl --user status bodyd` and `journalctl --user -u bodyd` say why it stopped.\n"
       "  bodyd on another endpoint: bodyd-ctl --control ENDPOINT (bodyd's --control flag or \"control\" config key).\n";
  if (curve)
    m += "  With CURVE: is --curve-server-key bodyd's server.public, and is this client's key in bodyd's --curve-allow "
         "directory?\n";
  return m;
}

// One request; nullopt when no reply came within the timeout.
std::optional<json> request(bodyd::client::Client& client, const json& req, double timeout_s) {
  bodyd::client::ControlReply reply =
      client.request(req, std::chrono::milliseconds(std::lround(timeout_s * 1000)));
  if (reply.timed_out) return std::nullopt;
  if (!reply.json.is_object()) return json{{"ok", false}, {"error", reply.error}};
  return std::move(reply.json);
}

// ------------------------------------------------------------------ human-readable replies

std::string duration_text(double s) {
  const auto total = static_cast<long long>(s);
  if (total < 60) return fmt::format("{:.1f} s", s);
  if (total < 3600) return fmt::format("{}m {:02}s", total / 60, total % 60);
  return fmt::format("{}h {:02}m {:02}s", total / 3600, (total / 60) % 60, total % 60);
}

std::string ms(const json& us) { return us.is_number() ? fmt::format("{:.2f} ms", us.get<double>() / 1000.0) : "-"; }

std::string percentiles(const json& t) {
  if (!t.is_object() || t.value("count", 0) == 0) return "none yet";
  std::string s = fmt::format("p50 {}", ms(t.value("p50", json())));
  if (t.contains("p90")) s += ", p90 " + ms(t["p90"]);
  s += fmt::format(", p99 {}, max {}", ms(t.value("p99", json())), ms(t.value("max", json())));
  if (t.contains("window")) s += fmt::format(" (last {} poses)", t["window"].dump());
  return s;
}

std::string calibration_text(const json& r) {
  std::string s;
  const double head = r.value("head_height_m", 0.0);
  if (r.value("height_calibrated", false))
    s = fmt::format("head height {:.3f} m (body about {:.2f} m), calibrated", head, r.value("user_height_m", 0.0));
  else
    s = fmt::format("head height {:.3f} m: the model's own size, not calibrated (bodyd-ctl calibrate)", head);
  // Where it came from (docs/control.md: calibration_source, auto_calibration).
  const std::string source = r.value("calibration_source", ""), automatic = r.value("auto_calibration", "");
  if (source == "auto") s += fmt::format(" automatically ({})", automatic == "fallback" ? "never still: from the head's 90th percentile height" : "from a still half second");
  else if (source == "control") s += " by bodyd-ctl calibrate";
  else if (source == "config") s += " by the configuration";
  else if (source == "file") s += " by the calibration pose kept in the mounting file";
  if (automatic == "waiting") s += "; auto calibration waiting for the head to hold still";
  if (r.contains("offsets_configured"))
    s += r["offsets_configured"].get<bool>() ? "; device offsets configured" : "; no device offsets";
  if (r.contains("recentred")) s += r["recentred"].get<bool>() ? "; re-centred" : "; not re-centred";
  return s;
}

// The device mounting (docs/control.md, "mounting"): per role where it came from and how far it
// is from the default.
std::string mounting_text(const json& m) {
  if (!m.is_object() || !m.contains("roles")) return "none";
  std::string s;
  // The headset and controllers, then the body trackers bodyd lists (those measured).
  for (const bodyd::Role each : bodyd::kRoles) {
    const std::string role(bodyd::role_name(each));
    if (!m["roles"].contains(role)) continue;
    const json& r = m["roles"][role];
    const std::string origin = r.value("origin", std::string("?"));
    s += fmt::format("{}{} {}", s.empty() ? "" : "; ", role,
                     origin == "default" ? std::string("default")
                     : origin == "pose"  ? std::string("calibration pose")
                     : origin == "file"  ? std::string("calibration pose (mounting file)")
                     : origin == "auto"  ? std::string("auto (a still second)")
                                         : origin);
    if (r.contains("offset_cm"))  // a body tracker: no default
      s += fmt::format(" ({:.1f} cm from its joint)", r.value("offset_cm", 0.0));
    else if (origin != "default")
      s += fmt::format(" ({:.1f} deg, {:.1f} cm from the default)", r.value("from_default_deg", 0.0), r.value("from_default_cm", 0.0));
    if (!r.value("device_frames", false)) s += ", no device poses yet";
  }
  return s;
}

// A JSON value of an output's status as text: strings bare, arrays as "a, b", numbers as JSON.
std::string value_text(const json& v) {
  if (v.is_string()) return v.get<std::string>();
  if (v.is_boolean()) return v.get<bool>() ? "yes" : "no";
  if (v.is_array()) {
    std::string s;
    for (const auto& e : v) s += (s.empty() ? "" : ", ") + value_text(e);
    return s.empty() ? "none" : s;
  }
  return v.dump();
}

// One output of the status reply (docs/control.md, "outputs"): its name, what it sent, its
// rate limit and last error, then the output's own keys (docs/outputs.md) as "key value".
std::string output_text(const json& o) {
  if (!o.is_object()) return value_text(o);
  std::string s = fmt::format("{}: {} sent, {} failed", o.value("name", std::string("?")), value_text(o.value("sent", json(0))),
                              value_text(o.value("send_failed", json(0))));
  const double rate = o.value("rate_hz", 0.0);
  if (rate > 0)
    s += fmt::format(", at most {} poses/s ({} skipped)", value_text(o["rate_hz"]),
                     value_text(o.value("skipped_by_rate", json(0))));
  for (const auto& [key, value] : o.items()) {
    if (key == "name" || key == "sent" || key == "send_failed" || key == "rate_hz" || key == "skipped_by_rate" ||
        key == "last_error")
      continue;
    std::string name = key;
    std::replace(name.begin(), name.end(), '_', ' ');
    s += ", " + name + " " + value_text(value);
  }
  const std::string err = o.value("last_error", std::string());
  if (!err.empty()) s += "; last error: " + err;
  return s;
}

void print_status(const json& r) {
  std::cout << fmt::format("bodyd: up {}, method {}", duration_text(r.value("uptime_s", 0.0)), r.value("method", std::string("?")));
  const std::string model = r.value("model", std::string());
  if (!model.empty()) std::cout << " (" << model << ")";
  std::cout << "\n";
  std::cout << "sources:";
  const json sources = r.value("sources", json::array());
  if (sources.empty()) std::cout << " none";
  std::cout << "\n";
  for (const auto& s : sources) {
    std::string state = s.value("finished", false) ? "finished" : s.value("connected", false) ? "connected" : "not connected";
    std::cout << fmt::format("  {}: {}, {:.1f} Hz, {} samples", s.value("name", std::string("?")), state,
                             s.value("rate_hz", 0.0), s.value("samples", json(0)).dump());
    // The rate is every role's together (a headset and two controllers at 90 Hz: 270 Hz).
    if (const json by_role = s.value("rate_hz_by_role", json::object()); by_role.is_object() && !by_role.empty()) {
      std::string roles;
      for (const auto& [role, hz] : by_role.items()) {
        std::string name = role;
        std::replace(name.begin(), name.end(), '_', ' ');
        if (hz.is_number()) roles += fmt::format("{}{} {:.1f} Hz", roles.empty() ? "" : ", ", name, hz.get<double>());
      }
      std::cout << " (" << roles << ")";
    }
    const std::string err = s.value("last_error", std::string());
    if (!err.empty()) std::cout << ", last error: " << err;
    std::cout << "\n";
  }
  if (!r.value("sources_started", true)) std::cout << "  (sources wait for a subscriber: --wait-for-subscriber)\n";
  // Every role with its state, source and rate (issue 44).
  if (const json trackers = r.value("trackers", json::object()); trackers.is_object() && !trackers.empty()) {
    std::string line;
    for (const bodyd::Role each : bodyd::kRoles) {
      const std::string role(bodyd::role_name(each));
      if (!trackers.contains(role)) continue;
      const json& t = trackers[role];
      std::string name = role;
      std::replace(name.begin(), name.end(), '_', ' ');
      line += fmt::format("{}{} {}", line.empty() ? "" : "; ", name, t.value("state", std::string("?")));
      if (t.contains("source"))
        line += fmt::format(" ({}, {:.0f} Hz)", t.value("source", std::string("?")), t.value("rate_hz", 0.0));
    }
    std::cout << "trackers: " << line << "\n";
  }
  const json by_role = r.value("samples_by_role", json::object());
  std::cout << fmt::format("samples: {} in (head {}, left hand {}, right hand {}), {} dropped, queue {}/{}\n",
                           r.value("samples_in", json(0)).dump(), by_role.value("head", json(0)).dump(),
                           by_role.value("left_hand", json(0)).dump(), by_role.value("right_hand", json(0)).dump(),
                           r.value("samples_dropped", json(0)).dump(), r.value("queue_depth", json(0)).dump(),
                           r.value("queue_capacity", json(0)).dump());
  std::cout << fmt::format("poses: {} out", r.value("frames_out", json(0)).dump());
  if (r.contains("poses_per_s")) std::cout << fmt::format(" ({:.1f}/s)", r["poses_per_s"].get<double>());
  std::cout << fmt::format(", {} not ready, {} skipped by rate_hz, {} send failures; {} subscriptions\n",
                           r.value("frames_not_ready", json(0)).dump(), r.value("frames_skipped_by_rate", json(0)).dump(),
                           r.value("sends_failed", json(0)).dump(), r.value("subscriptions", json(0)).dump());
  std::cout << "reconstruction: " << percentiles(r.value("reconstruct_us", json())) << "\n";
  std::cout << "latency (sample arrival -> pose sent): " << percentiles(r.value("latency_us", json())) << "\n";
  std::cout << "calibration: " << calibration_text(r) << "\n";
  if (r.contains("mounting")) std::cout << "device mounting: " << mounting_text(r["mounting"]) << "\n";
  if (r.contains("outputs") && r["outputs"].is_array() && !r["outputs"].empty()) {
    std::cout << "outputs:\n";
    for (const auto& o : r["outputs"]) std::cout << "  " << output_text(o) << "\n";
  }
  std::cout << fmt::format("endpoints: poses {}, control {}{}\n", r.value("pub", std::string("?")),
                           r.value("control", std::string("?")), r.value("curve", false) ? ", CURVE on" : "");
}

void print_reply(const std::string& cmd, const json& r) {
  if (cmd == "status") return print_status(r);
  if (cmd == "calibrate") {
    std::cout << "calibrated: " << calibration_text(r) << "\n";
    if (r.contains("mounting")) {
      std::cout << "device mounting: " << mounting_text(r["mounting"]) << "\n";
      if (r.contains("roles"))
        for (const auto& [role, e] : r["roles"].items())
          std::cout << fmt::format("  {}: {:.1f} deg from the default (a person's pose varies by about {:.0f} deg), "
                                   "held still within {:.1f} deg\n",
                                   role, e.value("from_default_deg", 0.0), e.value("sd_deg", 0.0), e.value("motion_deg", 0.0));
      if (r.contains("note")) std::cout << "  " << r["note"].get<std::string>() << "\n";
      if (r.contains("mounting_file")) std::cout << "  kept in " << r["mounting_file"].get<std::string>() << "\n";
      if (r.contains("mounting_file_error")) std::cout << "  not kept: " << r["mounting_file_error"].get<std::string>() << "\n";
    }
  }
  else if (cmd == "recenter" || cmd == "reset") {
    std::cout << "re-centred: the current facing is forward";
    if (r.contains("heading_deg")) std::cout << fmt::format(" (turned by {:.1f} degrees)", r["heading_deg"].get<double>());
    std::cout << "\n";
  } else if (cmd == "reload-model") {
    std::cout << "model reloaded: method " << r.value("method", std::string("?"));
    if (r.contains("model")) std::cout << ", " << r["model"].get<std::string>();
    std::cout << "\n";
  } else if (cmd == "shutdown") std::cout << "bodyd is shutting down\n";
  else std::cout << r.dump(2) << "\n";
}

// bodyd waits this long for the calibration pose's still second.
constexpr double kPoseWaitS = 5.0;

// The steps of the calibration pose, then a countdown of `seconds` (one number a second), then
// "hold still": the request is sent right after.
void count_down(int seconds) {
  std::cerr << "bodyd-ctl: stand straight, look ahead, arms relaxed at your sides, controllers pointing forward... ";
  for (int left = seconds; left > 0; --left) {
    std::cerr << left << "... " << std::flush;
    std::this_thread::sleep_for(std::chrono::seconds(1));
  }
  std::cerr << "hold still" << std::endl;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bodyd-ctl: ask a running bodyd for its status, calibrate, re-centre, reload the model, stop it "
               "(docs/ctl.md)"};
  app.set_version_flag("--version", "bodyd-ctl 0.1.0");
  app.require_subcommand(1);
  std::string control, endpoints_file, server_key, client_key;
  double timeout_s = 3.0;
  bool as_json = false;
  app.add_option("--control", control, "bodyd's control endpoint (default: \"control\" in the user config, else " +
                                           std::string(kDefaultControl) + ")");
  app.add_option("--endpoints-file", endpoints_file, "read the control endpoint from bodyd's --endpoints-file");
  app.add_option("--timeout-s", timeout_s, "how long to wait for the answer")->check(CLI::PositiveNumber);
  app.add_option("--curve-server-key", server_key, "bodyd's server.public (when bodyd uses CURVE)");
  app.add_option("--curve-client-key", client_key,
                 "this client's secret key file (bodyd --gen-keys DIR --client NAME), when bodyd has --curve-allow");
  app.add_flag("--json", as_json, "print bodyd's reply as JSON");

  auto* status = app.add_subcommand("status", "sources and rates, poses out, drops, timing, calibration");
  status->add_flag("--json", as_json, "print the raw JSON reply");

  auto* calibrate = app.add_subcommand("calibrate", "set the user's size (exactly one option)");
  double head_height_m = 0.0, height_m = 0.0;
  bool from_head = false, pose = false;
  auto* o_head = calibrate->add_option("--head-height-m", head_height_m, "standing head height, metres (exact)");
  auto* o_height = calibrate->add_option("--height-m", height_m, "body height, metres (head height = 0.90 x this)");
  auto* o_from = calibrate->add_flag("--from-head", from_head, "take the current head tracker height (stand up straight)");
  auto* o_pose = calibrate->add_flag(
      "--pose", pose,
      "the calibration pose: stand straight, look ahead, arms relaxed at the sides, hold still for one "
      "second; learns how the headset and controllers sit on you, and your height (docs/vr-apps.md)");
  int pose_in_s = 0;
  calibrate
      ->add_option("--in", pose_in_s,
                   "with --pose: count down SECONDS (0 to 30) with the steps, to get into the pose, then ask bodyd")
      ->check(CLI::Range(0, 30))
      ->needs(o_pose);
  o_head->excludes(o_height)->excludes(o_from);
  o_height->excludes(o_from);

  app.add_subcommand("recenter", "re-centre: the user's current facing becomes forward");
  app.add_subcommand("reset", "the old name of recenter, still accepted");
  auto* reload = app.add_subcommand("reload-model", "load the model file again, or another one");
  std::string model_path;
  reload->add_option("PATH", model_path, "model file (default: the one in use)");
  app.add_subcommand("shutdown", "stop bodyd");
  app.add_subcommand("skeleton", "the skeleton the poses follow (JSON)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitUsage;
  }

  const std::string cmd = app.get_subcommands().front()->get_name();
  json req{{"cmd", cmd}};
  if (cmd == "calibrate") {
    const int given = int(o_head->count() > 0) + int(o_height->count() > 0) + int(from_head) + int(pose);
    if (given != 1) {
      std::cerr << "bodyd-ctl calibrate: give exactly one of --head-height-m H, --height-m H, --from-head or --pose\n";
      return kExitUsage;
    }
    if (pose) {
      req["from"] = "pose";
      req["timeout_s"] = kPoseWaitS;
    } else if (from_head) req["from"] = "head";
    else if (o_head->count() > 0) req["head_height_m"] = head_height_m;
    else req["user_height_m"] = height_m;
  } else if (cmd == "reload-model" && !model_path.empty()) {
    // bodyd resolves a relative path against its own working directory, not ours.
    std::error_code ec;
    const fs::path absolute = fs::absolute(model_path, ec);
    req["path"] = ec ? model_path : absolute.lexically_normal().string();
  }

  std::string error;
  const auto target = choose_target(control, endpoints_file, error);
  if (!target) {
    std::cerr << "bodyd-ctl: " << error << "\n";
    return kExitUsage;
  }
  const auto curve = load_curve(server_key, client_key, error);
  if (!error.empty()) {
    std::cerr << "bodyd-ctl: " << error << "\n";
    return kExitUsage;
  }
  bodyd::client::ClientOptions options;
  options.pose_endpoint.clear();  // control requests only
  options.control_endpoint = target->endpoint;
  if (curve) {
    options.curve_server_key = curve->server_public;
    options.curve_secret_key = curve->client_secret;
  }
  const std::unique_ptr<bodyd::client::Client> client = bodyd::client::Client::connect(options, error);
  if (!client) {
    std::cerr << "bodyd-ctl: " << target->endpoint << " (" << target->from << "): " << error << "\n";
    return kExitUsage;
  }
  if (pose) {
    // Nobody should count down to learn that bodyd is not there: ask it something first.
    if (pose_in_s > 0 && !request(*client, json{{"cmd", "status"}}, timeout_s)) {
      std::cerr << no_answer_message(*target, timeout_s, curve.has_value());
      return kExitNoAnswer;
    }
    count_down(pose_in_s);
    timeout_s = std::max(timeout_s, kPoseWaitS + 3.0);  // bodyd answers within its wait
  }
  const std::optional<json> reply = request(*client, req, timeout_s);
  if (!reply) {
    std::cerr << no_answer_message(*target, timeout_s, curve.has_value());
    return kExitNoAnswer;
  }
  if (!reply->value("ok", false)) {
    if (as_json) std::cout << reply->dump(2) << "\n";
    std::cerr << "bodyd-ctl " << cmd << ": bodyd says: " << reply->value("error", reply->dump()) << "\n";
    return kExitError;
  }
  if (as_json) std::cout << reply->dump(2) << "\n";
  else print_reply(cmd, *reply);
  return 0;
}
