// The control socket's requests (docs/control.md): JSON in, JSON out.
//
// handle_control_request() parses and checks a request and calls the matching ControlTarget
// function; it never throws and always returns a JSON object with "ok". Malformed requests
// (not JSON, not an object, no "cmd", wrong types, unknown commands or keys) get
// {"ok": false, "error": "..."} saying what is wrong.
#pragma once

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <string_view>

namespace bodyd::daemon {

// What the control socket can ask of the daemon. Called on the control thread. Each returns
// the reply object, "ok" included.
class ControlTarget {
 public:
  virtual ~ControlTarget() = default;
  virtual nlohmann::json status() = 0;
  virtual nlohmann::json skeleton() = 0;
  // The standing head height (metres) the reconstructor scales by; 0 restores the model's size.
  virtual nlohmann::json calibrate_height(double head_height_m) = 0;
  virtual nlohmann::json calibrate_from_head() = 0;
  virtual nlohmann::json reload_model(const std::optional<std::string>& path) = 0;
  virtual nlohmann::json shutdown() = 0;
  // Re-centres the tracking space: the user's current facing and floor position become forward
  // and the origin ("reset", docs/control.md). The default answers that it is not supported.
  virtual nlohmann::json recentre();
  // The calibration pose ({"cmd":"calibrate","from":"pose"}, docs/control.md): waits up to
  // `timeout_s` for a still second of the trackers and learns each device's mounting and the
  // height from it. The default answers that it is not supported.
  virtual nlohmann::json calibrate_pose(double timeout_s);
};

// The commands, for messages.
inline constexpr std::string_view kControlCommands = "status, skeleton, calibrate, reset, reload-model, shutdown";

// Bounds of a user height a calibration accepts (metres).
inline constexpr double kMinUserHeightM = 0.5;
inline constexpr double kMaxUserHeightM = 2.6;

[[nodiscard]] nlohmann::json handle_control_request(std::string_view request, ControlTarget& target);

// An error reply.
[[nodiscard]] nlohmann::json control_error(const std::string& message);

}  // namespace bodyd::daemon
