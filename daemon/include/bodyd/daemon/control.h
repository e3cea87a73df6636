// The control socket's requests (docs/control.md): JSON in, JSON out.
//
// answer_control_request() parses a request, finds its row in the table of requests
// (control_requests()) by "cmd", and the row checks the request's keys and values and calls the
// matching ControlTarget function; it never throws and always answers a JSON object with "ok",
// now or, for a request that waits (the calibration pose), later. Malformed requests (not JSON,
// not an object, no "cmd", wrong types, unknown commands or keys) get {"ok": false, "error":
// "..."} saying what is wrong.
//
// A new request is one ControlTarget function, one row of the table (daemon/src/control.cpp)
// and its section in docs/control.md (tests/daemon/control_requests_test.cpp checks that the
// docs and the table list the same requests).
#pragma once

#include <nlohmann/json.hpp>

#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>

namespace bodyd::daemon {

// The answer to a request that waits for something (calibrate "from": "pose" waits for a still
// second): called on the control thread between other requests until it returns the reply, so a
// wait never holds up `status` or anything else. It must not block.
using LaterReply = std::function<std::optional<nlohmann::json>()>;

// A request's answer: the reply now, or (`later` set) a reply to collect later.
struct ControlReply {
  ControlReply(nlohmann::json now) : reply(std::move(now)) {}  // NOLINT(google-explicit-constructor): a plain reply
  explicit ControlReply(LaterReply pending) : later(std::move(pending)) {}
  nlohmann::json reply;  // when `later` is empty
  LaterReply later;
};

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
  // and the origin ("recenter", old name "reset", docs/control.md). The default answers that it
  // is not supported.
  virtual nlohmann::json recentre();
  // The calibration pose ({"cmd":"calibrate","from":"pose"}, docs/control.md): starts waiting up
  // to `timeout_s` for a still second of the trackers, from which it learns each device's
  // mounting and the height; the reply comes later (ControlReply::later). The default answers at
  // once that it is not supported.
  virtual ControlReply calibrate_pose(double timeout_s);
};

// One request of the control socket: a row of the table.
struct ControlRequest {
  std::string_view name;      // its "cmd"
  std::string_view alias_of;  // empty for a request; else the name of the request this old name stands for
  std::string_view help;      // one line, as bodyd-ctl's --help says it
  std::string_view docs;      // its section of docs/control.md, "### `DOCS`" (an old name: its request's)
  // Checks the request's keys and values and calls the target; an error reply when they are
  // wrong. `cmd` is the name the request used (for messages).
  ControlReply (*handle)(const nlohmann::json& request, std::string_view cmd, ControlTarget& target);
};

// The table of requests, in the order messages list them; old names last.
[[nodiscard]] std::span<const ControlRequest> control_requests();

// The requests' names for messages ("status, skeleton, ..."), old names left out.
[[nodiscard]] std::string control_request_names();

// Bounds of a user height a calibration accepts (metres).
inline constexpr double kMinUserHeightM = 0.5;
inline constexpr double kMaxUserHeightM = 2.6;

// The control socket's entry: the reply, or the LaterReply to poll for it.
[[nodiscard]] ControlReply answer_control_request(std::string_view request, ControlTarget& target);
// The same, waiting for a later reply (polling it every 10 ms): for callers with nothing else to
// answer meanwhile (tests, fuzzing).
[[nodiscard]] nlohmann::json handle_control_request(std::string_view request, ControlTarget& target);

// An error reply.
[[nodiscard]] nlohmann::json control_error(const std::string& message);

}  // namespace bodyd::daemon
