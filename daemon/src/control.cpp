#include "bodyd/daemon/control.h"

#include "bodyd/daemon/config.h"

#include <chrono>
#include <cmath>
#include <initializer_list>
#include <thread>

namespace bodyd::daemon {
namespace {

using nlohmann::json;

// Empty when every key of `request` is one of `allowed`.
std::string unknown_key(const json& request, const std::string& cmd, std::initializer_list<std::string_view> allowed) {
  for (const auto& [key, value] : request.items()) {
    bool known = key == "cmd";
    for (auto a : allowed) known |= key == a;
    if (!known) {
      std::string list = "cmd";
      for (auto a : allowed) list += ", " + std::string(a);
      return "unknown key \"" + key + "\" for cmd \"" + cmd + "\" (allowed: " + list + ")";
    }
  }
  return {};
}

ControlReply dispatch(const json& request, ControlTarget& target) {
  if (!request.is_object()) return control_error("a request is a JSON object like {\"cmd\":\"status\"}");
  const auto cmd_it = request.find("cmd");
  if (cmd_it == request.end())
    return control_error("missing \"cmd\" (one of " + std::string(kControlCommands) + ")");
  if (!cmd_it->is_string()) return control_error("\"cmd\" must be a string, got " + std::string(cmd_it->type_name()));
  const std::string cmd = cmd_it->get<std::string>();

  if (cmd == "status" || cmd == "skeleton" || cmd == "shutdown" || cmd == "reset") {
    if (auto e = unknown_key(request, cmd, {}); !e.empty()) return control_error(e);
    if (cmd == "status") return target.status();
    if (cmd == "skeleton") return target.skeleton();
    if (cmd == "reset") return target.recentre();
    return target.shutdown();
  }
  if (cmd == "calibrate") {
    if (auto e = unknown_key(request, cmd, {"user_height_m", "head_height_m", "from", "timeout_s"}); !e.empty())
      return control_error(e);
    const int given = int(request.contains("user_height_m")) + int(request.contains("head_height_m")) +
                      int(request.contains("from"));
    if (given != 1)
      return control_error(
          "calibrate takes exactly one of \"user_height_m\": METRES (body height), \"head_height_m\": METRES "
          "(standing head height) or \"from\": \"head\" or \"pose\"");
    if (request.contains("from")) {
      const json& from = request["from"];
      const std::string what = from.is_string() ? from.get<std::string>() : std::string();
      if (what != "head" && what != "pose")
        return control_error(
            "calibrate \"from\" must be \"head\" (the height from the standing head height) or \"pose\" (the "
            "calibration pose: stand straight, look ahead, arms relaxed at the sides, for one second)");
      double timeout_s = 5.0;
      if (request.contains("timeout_s")) {
        if (what != "pose") return control_error("calibrate: \"timeout_s\" goes only with \"from\": \"pose\"");
        const json& t = request["timeout_s"];
        if (!t.is_number() || !std::isfinite(t.get<double>()) || t.get<double>() < 1.0 || t.get<double>() > 30.0)
          return control_error("calibrate \"timeout_s\" must be a number of seconds from 1 to 30");
        timeout_s = t.get<double>();
      }
      if (what == "pose") return target.calibrate_pose(timeout_s);
      return target.calibrate_from_head();
    }
    const char* key = request.contains("user_height_m") ? "user_height_m" : "head_height_m";
    const json& h = request[key];
    if (!h.is_number()) return control_error(std::string("\"") + key + "\" must be a number (metres), got " + h.type_name());
    const double height_m = h.get<double>();
    if (!std::isfinite(height_m) || (height_m != 0.0 && (height_m < kMinUserHeightM || height_m > kMaxUserHeightM)))
      return control_error(std::string("\"") + key + "\" must be in metres between 0.5 and 2.6 (0 restores the model's size)");
    return target.calibrate_height(key == std::string_view("user_height_m") ? height_m * kHeadHeightPerStature : height_m);
  }
  if (cmd == "reload-model") {
    if (auto e = unknown_key(request, cmd, {"path"}); !e.empty()) return control_error(e);
    std::optional<std::string> path;
    if (request.contains("path")) {
      const json& p = request["path"];
      if (!p.is_string() || p.get<std::string>().empty())
        return control_error("\"path\" must be a non-empty string (a model file)");
      path = p.get<std::string>();
    }
    return target.reload_model(path);
  }
  return control_error("unknown cmd \"" + cmd + "\" (one of " + std::string(kControlCommands) + ")");
}

}  // namespace

json control_error(const std::string& message) { return json{{"ok", false}, {"error", message}}; }

json ControlTarget::recentre() { return control_error("reset: re-centring is not supported here"); }
ControlReply ControlTarget::calibrate_pose(double) { return control_error("calibrate from pose: not supported here"); }

ControlReply answer_control_request(std::string_view request, ControlTarget& target) {
  json parsed = json::parse(request.begin(), request.end(), nullptr, /*allow_exceptions=*/false);
  if (parsed.is_discarded()) return control_error("the request is not valid JSON; send e.g. {\"cmd\":\"status\"}");
  try {
    return dispatch(parsed, target);
  } catch (const std::exception& e) {
    // A target failing is a bug or an unexpected state, reported rather than killing the control thread.
    return control_error(std::string("internal error: ") + e.what());
  }
}

json handle_control_request(std::string_view request, ControlTarget& target) {
  ControlReply answer = answer_control_request(request, target);
  if (!answer.later) return std::move(answer.reply);
  for (;;) {
    try {
      if (std::optional<json> reply = answer.later()) return std::move(*reply);
    } catch (const std::exception& e) {
      return control_error(std::string("internal error: ") + e.what());
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

}  // namespace bodyd::daemon
