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
std::string unknown_key(const json& request, std::string_view cmd, std::initializer_list<std::string_view> allowed) {
  for (const auto& [key, value] : request.items()) {
    bool known = key == "cmd";
    for (auto a : allowed) known |= key == a;
    if (!known) {
      std::string list = "cmd";
      for (auto a : allowed) list += ", " + std::string(a);
      return "unknown key \"" + key + "\" for cmd \"" + std::string(cmd) + "\" (allowed: " + list + ")";
    }
  }
  return {};
}

// The handlers of the table's rows: each checks its request and calls the target.

ControlReply handle_status(const json& request, std::string_view cmd, ControlTarget& target) {
  if (auto e = unknown_key(request, cmd, {}); !e.empty()) return control_error(e);
  return target.status();
}

ControlReply handle_skeleton(const json& request, std::string_view cmd, ControlTarget& target) {
  if (auto e = unknown_key(request, cmd, {}); !e.empty()) return control_error(e);
  return target.skeleton();
}

ControlReply handle_calibrate(const json& request, std::string_view cmd, ControlTarget& target) {
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

ControlReply handle_recenter(const json& request, std::string_view cmd, ControlTarget& target) {
  if (auto e = unknown_key(request, cmd, {}); !e.empty()) return control_error(e);
  return target.recentre();
}

ControlReply handle_reload_model(const json& request, std::string_view cmd, ControlTarget& target) {
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

ControlReply handle_shutdown(const json& request, std::string_view cmd, ControlTarget& target) {
  if (auto e = unknown_key(request, cmd, {}); !e.empty()) return control_error(e);
  return target.shutdown();
}

// The table of requests (control.h, ControlRequest): name, old name of, help, docs section, handler.
constexpr ControlRequest kRequests[] = {
    {"status", "", "sources and rates, poses out, drops, timing, calibration", "status", handle_status},
    {"skeleton", "", "the skeleton the poses follow (JSON)", "skeleton", handle_skeleton},
    {"calibrate", "", "set the user's size (exactly one option)", "calibrate", handle_calibrate},
    {"recenter", "", "re-centre: the user's current facing becomes forward", "recenter", handle_recenter},
    {"reload-model", "", "load the model file again, or another one", "reload-model", handle_reload_model},
    {"shutdown", "", "stop bodyd", "shutdown", handle_shutdown},
    // Old names, still accepted.
    {"reset", "recenter", "the old name of recenter, still accepted", "recenter", handle_recenter},
};

ControlReply dispatch(const json& request, ControlTarget& target) {
  if (!request.is_object()) return control_error("a request is a JSON object like {\"cmd\":\"status\"}");
  const auto cmd_it = request.find("cmd");
  if (cmd_it == request.end()) return control_error("missing \"cmd\" (one of " + control_request_names() + ")");
  if (!cmd_it->is_string()) return control_error("\"cmd\" must be a string, got " + std::string(cmd_it->type_name()));
  const std::string cmd = cmd_it->get<std::string>();
  for (const ControlRequest& row : kRequests)
    if (row.name == cmd) return row.handle(request, cmd, target);
  return control_error("unknown cmd \"" + cmd + "\" (one of " + control_request_names() + ")");
}

}  // namespace

json control_error(const std::string& message) { return json{{"ok", false}, {"error", message}}; }

std::span<const ControlRequest> control_requests() { return kRequests; }

std::string control_request_names() {
  std::string names;
  for (const ControlRequest& row : kRequests)
    if (row.alias_of.empty()) names += (names.empty() ? "" : ", ") + std::string(row.name);
  return names;
}

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
