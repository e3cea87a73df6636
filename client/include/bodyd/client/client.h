// bodyd C++ client: subscribe to the pose stream, receive poses as typed structs, talk to
// the control socket. Protocol: docs/protocol.md; control requests: docs/control.md.
//
// Threading: a Client is used by one thread at a time (ZeroMQ sockets are not thread-safe).
// Errors: nothing here throws. receive() reports "no pose yet" as a value (kTimeout); a
// message that cannot be decoded is reported (kMalformed) and skipped, and the stream goes on.
#pragma once

#include "bodyd/protocol/pose_message.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace bodyd::client {

struct ClientOptions {
  // The daemon's PUB endpoint (bodyd binds, we connect); empty for none (a control client:
  // receive() then fails).
  std::string pose_endpoint{protocol::kDefaultPoseEndpoint};
  // The daemon's control (REP) endpoint; empty for none (request() and skeleton() then fail).
  std::string control_endpoint{protocol::kDefaultControlEndpoint};
  // CURVE (docs/daemon.md, "Security"), for both sockets: the daemon's public key, Z85 text
  // (bodyd/client/curve_keys.h reads the key files); empty for none. With it, this client's key
  // pair: both empty for a fresh pair (enough when bodyd has no --curve-allow list), or the
  // secret key alone (the public key is computed from it).
  std::string curve_server_key;
  std::string curve_public_key;
  std::string curve_secret_key;
  // Messages queued in this process before newer ones are dropped (ZMQ_RCVHWM). A consumer
  // that only wants the newest pose can drain with timeout 0 and keep the last one.
  int receive_hwm = 1000;
  // Per-request limit of request() and skeleton() when a call does not give one.
  std::chrono::milliseconds control_timeout{1000};
};

enum class Received {
  kPose,       // `out` holds a new pose
  kTimeout,    // nothing arrived within the timeout (not an error)
  kMalformed,  // a message could not be decoded (error() says why); it was skipped
  kError,      // the socket failed (error() says why)
};

// Counters since connect.
struct ClientStats {
  std::uint64_t poses = 0;      // poses received and decoded
  std::uint64_t dropped = 0;    // poses missing between received ones (seq gaps)
  std::uint64_t malformed = 0;  // messages that could not be decoded
  std::uint64_t skeletons = 0;  // skeleton messages received on the stream
  std::uint64_t restarts = 0;   // seq went backwards: the publisher restarted
};

// A control reply: `json` is the reply object; ok mirrors its "ok" field, and `error` is the
// reply's "error" text or, when no reply came, what went wrong (timeout, bad JSON, socket).
struct ControlReply {
  bool ok = false;
  nlohmann::json json;
  std::string error;
  bool timed_out = false;  // no reply came within the timeout (is the daemon running?)
};

class Client {
 public:
  // Creates the sockets and connects. ZeroMQ connects asynchronously, so this succeeds
  // whether or not the daemon is running (it connects when the daemon appears, and again
  // after a restart). Returns nullptr and sets `error` for an invalid endpoint.
  [[nodiscard]] static std::unique_ptr<Client> connect(const ClientOptions& options, std::string& error);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Waits up to `timeout` for the next pose (0: only what is already queued). Skeleton
  // messages arriving meanwhile are kept (stream_skeleton()) and do not end the wait.
  [[nodiscard]] Received receive(protocol::PoseMessage& out, std::chrono::milliseconds timeout);

  // Why the last receive() / request() failed.
  [[nodiscard]] const std::string& error() const;

  // The newest skeleton received on the "skeleton" topic or by skeleton(), if any.
  [[nodiscard]] const std::optional<protocol::SkeletonMessage>& current_skeleton() const;

  // Sends a JSON request on the control socket and waits for the reply. A request that times
  // out resets the control socket, so the next request starts clean.
  [[nodiscard]] ControlReply request(const nlohmann::json& request);
  [[nodiscard]] ControlReply request(const nlohmann::json& request, std::chrono::milliseconds timeout);

  // Asks the control socket for the skeleton ({"cmd":"skeleton"}) and decodes the reply;
  // on success it also becomes current_skeleton().
  [[nodiscard]] protocol::Status skeleton(protocol::SkeletonMessage& out);
  [[nodiscard]] protocol::Status skeleton(protocol::SkeletonMessage& out, std::chrono::milliseconds timeout);

  [[nodiscard]] const ClientStats& stats() const;

 private:
  struct Impl;
  explicit Client(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The skeleton as JSON, as the control socket's skeleton reply carries it:
// {"skeleton_id": u32, "names": [...], "parents": [...], "offsets_m": [[x,y,z], ...]}.
[[nodiscard]] nlohmann::json skeleton_to_json(const protocol::SkeletonMessage& skeleton);
// The inverse; checks the fields, the skeleton's invariants and that skeleton_id matches the
// hash of docs/protocol.md.
[[nodiscard]] protocol::Status skeleton_from_json(const nlohmann::json& json, protocol::SkeletonMessage& out);

// The pose as one line of JSON, as bodyd-sub --json prints it: seq, t_ns, publish_t_ns, flags,
// skeleton_id, foot_contact, root {joint, position_m, heading_rad}, joints (an object keyed by
// joint name when `skeleton` matches the pose's skeleton_id, else an array) of [x, y, z] metres,
// and rotations likewise as [x, y, z, w] when with_rotations. Keys in that order; each float is
// written with the fewest digits that read back as the same float.
[[nodiscard]] nlohmann::ordered_json pose_to_json(const protocol::PoseMessage& pose, const protocol::SkeletonMessage* skeleton,
                                          bool with_rotations);

}  // namespace bodyd::client
