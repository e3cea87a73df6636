// Outputs: where the daemon sends each reconstructed pose (docs/outputs.md).
//
// Every output implements the narrow Output interface below, as every tracker source
// implements drivers::TrackerSource. The ZeroMQ pose stream (--pub, docs/protocol.md) is one
// output; `bodyd --output SPEC` (repeatable) and the config file's "outputs" list add others.
// A spec is SCHEME:TARGET?KEY=VALUE&KEY=VALUE, e.g. "vrchat:127.0.0.1:9000?slots=hip,feet&rate=60".
//
// Threading and timing: open() and close() run on the thread that starts and stops the
// daemon; send(), poll() and set_skeleton() on the reconstruction thread, right after each
// pose (send) or between poses (poll, at least every 20 ms). They must never block and never
// retry: a send that fails is reported (false), the daemon counts it and logs it at a limited
// rate, and the next pose is the retry. status() is called from the control thread.
// Each output has its own rate limit (the `rate` option, Hz; the daemon applies it, the
// output never sees the poses it skips).
//
// How to add an output (one new file plus one registration):
//   1. io/NAME/output_NAME.cpp (the protocol's own folder, docs/architecture.md): a class deriving from Output (its space(): User or Runtime,
//      below), and a factory
//        std::unique_ptr<Output> make_NAME_output(const OutputSpec&, const OutputEnv&, std::string& error);
//      that checks spec.target and spec.options (unknown option: an error naming it) and
//      returns nullptr with `error` set (what is wrong, what to do) when the spec is bad.
//      Sending OSC over UDP: io/osc/osc_sender.h (liblo messages, a non-blocking socket).
//      What outputs share (a `trackers`/`slots` list option and its joints, an OSC output's
//      host, port and sender): io/output_parts.h.
//   2. One line in the table of io/outputs.cpp: {"NAME", make_NAME_output, "help"}.
//   3. The file in io/CMakeLists.txt; the scheme, its options and its conversions in
//      docs/outputs.md.
#pragma once

#include "bodyd/inference/reconstructor.h"
#include "bodyd/motion/skeleton.h"
#include "bodyd/motion/tracker.h"
#include "bodyd/protocol/pose_message.h"

#include <nlohmann/json_fwd.hpp>

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::daemon {

// The newest sample of one role that reached the daemon (the reconstruction thread, first
// thing), valid or not, used or not: a body tracker's device pose that the reconstruction cannot
// use yet (its mounting not calibrated) counts, since the runtime that sent it has the tracker.
struct RoleArrival {
  std::int64_t arrival_ns = INT64_MIN;  // its SourceSample::arrival_ns (host monotonic); INT64_MIN: none yet
  std::uint16_t source_index = 0;       // its source (SourceSample::source_index)
};
using RoleArrivals = std::array<RoleArrival, kRoleCount>;  // by static_cast<int>(Role)

// The rule, defined here only (docs/outputs.md, "Tracked roles"): the user has a real tracker
// for a role while a sample of it arrived within this long. Long enough to span a tracker's
// short losses and a driver's reconnection (a second), short enough that a tracker switched off
// gives its role back soon.
inline constexpr std::int64_t kRealTrackerHoldNs = 5'000'000'000;
[[nodiscard]] constexpr bool real_tracker_recent(const RoleArrival& a, std::int64_t now_ns) {
  return a.arrival_ns != INT64_MIN && now_ns - a.arrival_ns <= kRealTrackerHoldNs;
}

// The space an output publishes in (issue 45 item 3), declared once per output and converted in
// one place (the daemon, before send()):
//  - User: the user's re-centred space (bodyd's space after `reset`, docs/control.md): apps that
//    draw bodyd's body themselves (zmq, vmc);
//  - Runtime: the space the sources' samples came in, where the runtime owns the head and the
//    app places the trackers next to it (vrchat: its head message is the headset as received;
//    steamvr, monado: the trackers go back into the runtime that sent the headset).
// Before any reset the two are the same.
enum class OutputSpace : std::uint8_t { User, Runtime };
[[nodiscard]] std::string_view space_name(OutputSpace space);

// One pose, as every output receives it. All references stay valid only during send().
struct OutputFrame {
  std::uint64_t seq = 0;
  std::int64_t t_ns = 0;        // the pose's time (its head sample's t_ns)
  std::int64_t arrival_ns = 0;  // host monotonic time the head sample reached the daemon
  const BodyPose& body;         // global joint poses in the output's space(), metres at calibrated size
  const Skeleton& skeleton;     // the skeleton of `body` (names, parents, rest offsets at calibrated size)
  const protocol::PoseMessage& message;            // the pose stream message (docs/protocol.md)
  const std::vector<std::uint8_t>& message_bytes;  // ... encoded
  // The head sample that triggered this pose, as its source delivered it: BEFORE the device
  // mounting, the offset and the re-centring, so in the Runtime space (the headset's own pose,
  // e.g. for VRChat's alignment). May be invalid.
  const TrackerSample& head_as_received;
  // Per role, its newest sample's arrival and source (above; the head's is this pose's own).
  // Where the user tracks a role: the steamvr output leaves out its virtual tracker for a role
  // SteamVR's driver sent a sample of within kRealTrackerHoldNs; the other outputs send every
  // role, following the body (docs/outputs.md, "Tracked roles").
  RoleArrivals role_arrivals{};
};

// A parsed output spec: SCHEME:TARGET?KEY=VALUE&... (docs/outputs.md).
struct OutputSpec {
  std::string text;     // as given, for messages and status
  std::string scheme;   // "zmq", "vrchat", ...
  std::string target;   // after "SCHEME:" up to "?" (may be empty: the output's default)
  std::map<std::string, std::string> options;  // the query; "rate" is taken out by the daemon
};

// Parses a spec; false with `error` set when malformed (no scheme, empty key, key twice).
[[nodiscard]] bool parse_output_spec(std::string_view text, OutputSpec& out, std::string& error);

// What an output factory may need from the daemon's configuration: made from the daemon's
// DaemonConfig (daemon/include/bodyd/daemon/config.h), the members of the same names, without
// io/ including the daemon's headers.
struct OutputEnv {
  OutputEnv() = default;
  template <class Config>
  explicit OutputEnv(const Config& config)
      : allow_remote(config.allow_remote),
        curve_secret_key_file(config.curve_secret_key_file),
        curve_allow_dir(config.curve_allow_dir),
        send_hwm(config.send_hwm) {}

  bool allow_remote = false;
  std::string curve_secret_key_file;  // set: CURVE on the ZeroMQ outputs
  std::string curve_allow_dir;        // set: only the client keys in DIR/*.public may connect (ZAP)
  int send_hwm = 1000;                // messages queued per subscriber before ZeroMQ drops
};

class Output {
 public:
  virtual ~Output() = default;
  // The spec it was made from, resolved ("vrchat:127.0.0.1:9000"): logs and status.
  [[nodiscard]] virtual std::string name() const = 0;
  // Opens sockets. Empty, or what is wrong and what to do.
  [[nodiscard]] virtual std::string open() = 0;
  // The space its frames' `body` is in (above). Declared by each output; the daemon converts.
  [[nodiscard]] virtual OutputSpace space() const = 0;
  // Sends one pose without blocking. False (and `out_error` set) when it could not be sent.
  [[nodiscard]] virtual bool send(const OutputFrame& frame, std::string& out_error) = 0;
  // Between poses: housekeeping (subscriptions, periodic messages). Never blocks.
  virtual void poll(std::int64_t now_ns) { (void)now_ns; }
  // The skeleton changed (start, before open(); calibration; model reload); `bytes` is the
  // encoded skeleton message (docs/protocol.md).
  virtual void set_skeleton(const Skeleton& skeleton, const std::vector<std::uint8_t>& bytes) {
    (void)skeleton, (void)bytes;
  }
  // Output-specific status keys (thread-safe), merged into the output's entry in `status`.
  [[nodiscard]] virtual nlohmann::json status() const;
  // Closes sockets (idempotent).
  virtual void close() {}
};

// A factory checks the spec's target and options and makes the output without any I/O (no
// socket, no file): the command line calls every factory once just to check the specs, so that a
// malformed one exits 2 (check_specs, config.h); open() does the rest.
using OutputFactory = std::unique_ptr<Output> (*)(const OutputSpec& spec, const OutputEnv& env, std::string& error);

struct OutputKind {
  std::string_view scheme;
  OutputFactory factory;
  std::string_view help;  // one line: "vrchat:[HOST:PORT] VRChat OSC trackers ..."
};

// The registered outputs (io/outputs.cpp).
[[nodiscard]] const std::vector<OutputKind>& output_kinds();

// Makes an output from a spec (the daemon takes the "rate" option out first). nullptr and
// `error` (naming the spec) when the scheme is unknown or the factory refuses the spec.
[[nodiscard]] std::unique_ptr<Output> make_output(const OutputSpec& spec, const OutputEnv& env, std::string& error);

// Takes option `key` out of `spec.options` as a rate in Hz (0 = every pose). False with
// `error` set when it is not 0 or a number in limits::kMinPoseRateHz .. kMaxRateHz.
[[nodiscard]] bool take_rate_option(OutputSpec& spec, double& out_rate_hz, std::string& error);

// "KEY (unknown option of SCHEME outputs: expected A, B)" if spec has an option not in
// `known`; empty when all are known.
[[nodiscard]] std::string check_options(const OutputSpec& spec, const std::vector<std::string_view>& known);

// A rate limit in pose time: with rate_hz > 0, a pose at t_ns passes only if t_ns has reached
// the next due time (a quarter period early is fine, so jitter does not halve the rate). A rate
// that was not checked is taken safely: 0, below 0 or NaN is no limit, others are clamped to
// limits::kMinPoseRateHz .. kMaxRateHz (rate_hz() says which).
class RateGate {
 public:
  explicit RateGate(double rate_hz = 0.0);
  [[nodiscard]] bool due(std::int64_t t_ns);
  [[nodiscard]] double rate_hz() const { return rate_hz_; }

 private:
  double rate_hz_ = 0.0;
  std::int64_t next_due_ns_ = INT64_MIN;
};

}  // namespace bodyd::daemon
