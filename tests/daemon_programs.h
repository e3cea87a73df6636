// What the tests that run bodyd and bodyd-ctl as processes share (tests/daemon, tests/tools):
// the programs, an idle bodyd, a pose subscriber and the status request.
#pragma once

#include "test_paths.h"

#include "bodyd/protocol/pose_message.h"
#include "bodyd/test/process.h"

#include <zmq.hpp>

#include <filesystem>
#include <optional>
#include <string>

namespace bodyd::test {

inline const std::string kBodyd = (bin_dir() / "bodyd").string();
inline const std::string kCtl = (bin_dir() / "bodyd-ctl").string();

// A SUB socket on `pub` taking every pose message (no receive limit, no linger).
inline zmq::socket_t pose_subscriber(zmq::context_t& ctx, const std::string& pub) {
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, 0);
  sub.set(zmq::sockopt::subscribe, std::string(protocol::kPoseTopic));
  sub.connect(pub);
  return sub;
}

// A bodyd (IK, no source) on ipc sockets in `dir`: poses on dir/pose, control on
// ipc_control(dir), its endpoints file dir/endpoints.json, its output files named "bodyd".
inline std::string ipc_control(const std::filesystem::path& dir) { return "ipc://" + (dir / "control").string(); }
inline Process idle_bodyd(const std::filesystem::path& dir) {
  return Process({kBodyd, "--method", "ik", "--pub", "ipc://" + (dir / "pose").string(), "--control", ipc_control(dir),
                  "--endpoints-file", (dir / "endpoints.json").string()},
                 {.output_dir = dir, .name = "bodyd"});
}

// The daemon's answer to {"cmd":"status"} on `control` (a fresh REQ socket); nullopt when none
// came within timeout_ms.
inline std::optional<std::string> status_reply(zmq::context_t& ctx, const std::string& control, int timeout_ms = 5000) {
  zmq::socket_t req(ctx, zmq::socket_type::req);
  req.set(zmq::sockopt::linger, 0);
  req.set(zmq::sockopt::rcvtimeo, timeout_ms);
  req.connect(control);
  req.send(zmq::buffer(std::string(R"({"cmd":"status"})")));
  zmq::message_t reply;
  if (!req.recv(reply)) return std::nullopt;
  return reply.to_string();
}

}  // namespace bodyd::test
