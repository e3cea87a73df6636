// SlimeVR's bridge protocol: the Unix socket that SlimeVR's OpenVR driver (SteamVR) and
// Monado's SolarXR feeder connect to (docs/protocol-slimevr-bridge.md, docs/vr-apps.md).
//
//   - The codec: pure functions (bytes in, struct out) for the frames (a uint32 little-endian
//     length that counts its own 4 bytes, then one protobuf ProtobufMessage, at most
//     kMaxFrameBytes in all) and their messages; fuzzed (tests/drivers/fuzz_slimevr.cpp).
//   - BridgeServer: one listening socket, its connections and one thread. The steamvr: source
//     (headset, controllers and body trackers in, as device poses) and the steamvr output
//     (virtual trackers out, io/slimevr/output_steamvr.cpp) on the same socket share one
//     server, found with shared_bridge(path). The monado: source is a server on $DIR/SlimeVRInput (Monado's feeder
//     speaks the same protocol).
//
// Threading: the server's thread accepts, reads, decodes and pushes samples; publish() (the
// output, on the reconstruction thread) encodes and writes without blocking: what the socket
// does not take is kept (at most kMaxPendingOutBytes per connection, else the connection is
// dropped and counted) and the thread writes it when the socket is writable.
//
// Security: the socket is made with mode 0600 in a directory that must be private (owned by
// the user, no access for others: $XDG_RUNTIME_DIR is; a missing directory is made with 0700).
#pragma once

#include "bodyd/base/non_copyable.h"
#include "bodyd/io/source.h"
#include "bodyd/motion/rotation.h"

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::drivers::slimevr {

// ---- the codec --------------------------------------------------------------------------------

// The driver's VRBRIDGE_MAX_MESSAGE_SIZE (src/bridge/BridgeTransport.hpp): a frame, its 4
// length bytes included, is at most this long; the driver drops a connection that sends more.
inline constexpr std::size_t kMaxFrameBytes = 1024;
inline constexpr std::size_t kFrameHeaderBytes = 4;

// SlimeVR's tracker roles (the driver's src/TrackerRole.hpp), as TrackerAdded.tracker_role.
namespace role {
inline constexpr std::int32_t kNone = 0, kWaist = 1, kLeftFoot = 2, kRightFoot = 3, kChest = 4, kLeftKnee = 5,
                              kRightKnee = 6, kLeftElbow = 7, kRightElbow = 8, kLeftShoulder = 9, kRightShoulder = 10,
                              kLeftHand = 11, kRightHand = 12, kLeftController = 13, kRightController = 14, kHead = 15,
                              kNeck = 16, kCamera = 17, kKeyboard = 18, kHmd = 19, kBeacon = 20, kGenericController = 21;
inline constexpr std::int32_t kMax = 21;
}  // namespace role

// TrackerStatus.status values.
namespace status {
inline constexpr std::int32_t kDisconnected = 0, kOk = 1, kBusy = 2, kError = 3, kOccluded = 4;
}

// Position.data_source values. The driver sends IMU while SteamVR tracks a device by rotation
// only (TrackingResult_Fallback_RotationOnly, with TrackerStatus OCCLUDED), FULL otherwise.
namespace data_source {
inline constexpr std::int32_t kNone = 0, kImu = 1, kPrecision = 2, kFull = 3;
}

enum class FrameResult : std::uint8_t {
  Frame,     // a whole frame is there: frame_bytes long, payload after the length
  NeedMore,  // not yet a whole frame (or not yet the 4 length bytes)
  TooLong,   // its length is above the limit: the stream cannot be trusted any more
  TooShort,  // its length is below 4 (it must count itself)
};

struct FrameView {
  FrameResult result = FrameResult::NeedMore;
  std::uint32_t declared_bytes = 0;  // the length field (when at least 4 bytes are there)
  std::size_t frame_bytes = 0;       // Frame: bytes to consume
  const std::uint8_t* payload = nullptr;
  std::size_t payload_bytes = 0;
};

// Looks at the first frame of `data[0, size)`.
[[nodiscard]] FrameView next_frame(const std::uint8_t* data, std::size_t size,
                                   std::size_t max_frame_bytes = kMaxFrameBytes);

// One decoded ProtobufMessage (the fields of the kind it holds; the others keep defaults).
struct Message {
  enum class Kind : std::uint8_t { Empty, Position, UserAction, TrackerAdded, TrackerStatus, Battery, Version };
  Kind kind = Kind::Empty;
  std::int32_t tracker_id = 0;
  // Position: OpenVR's raw tracking space (right-handed, +Y up, metres), rotation (x, y, z, w).
  bool has_position = false;
  float x = 0, y = 0, z = 0;
  float qx = 0, qy = 0, qz = 0, qw = 1;
  bool has_data_source = false;  // Position.data_source (data_source:: values)
  std::int32_t data_source = 0;
  // TrackerAdded
  std::string serial, name, manufacturer;
  std::int32_t role = 0;
  // TrackerStatus
  std::int32_t status = 0;
  // Version
  std::int32_t protocol_version = 0;
};

// Decodes one frame's payload. False with `error` set when it is not a ProtobufMessage.
[[nodiscard]] bool decode_message(const std::uint8_t* payload, std::size_t size, Message& out, std::string& error);

// "Position", "TrackerAdded", ...
[[nodiscard]] std::string_view kind_name(Message::Kind kind);

// Encodes framed messages, appending to `out`. Reuses its protobuf objects, so encoding
// positions does not allocate once `out` has capacity. Not thread-safe (one per user).
class Encoder : NonCopyable {
 public:
  Encoder();
  ~Encoder();

  void version(std::vector<std::uint8_t>& out, std::int32_t protocol_version);
  void tracker_added(std::vector<std::uint8_t>& out, std::int32_t id, const std::string& serial,
                     const std::string& name, std::int32_t role, const std::string& manufacturer);
  void tracker_status(std::vector<std::uint8_t>& out, std::int32_t id, std::int32_t status);
  void position(std::vector<std::uint8_t>& out, std::int32_t id, const Vec3& position_m, const Quat& rotation);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// ---- where the sockets are ----------------------------------------------------------------------

// The SlimeVR driver's socket name, and Monado's two.
inline constexpr std::string_view kDriverSocketName = "SlimeVRDriver";
inline constexpr std::string_view kMonadoRpcSocketName = "SlimeVRRpc";
inline constexpr std::string_view kMonadoInputSocketName = "SlimeVRInput";

// Where Monado's SolarXR driver looks first: $XDG_RUNTIME_DIR; without it
// $XDG_DATA_HOME/dev.slimevr.SlimeVR (or ~/.local/share/dev.slimevr.SlimeVR). Empty (and
// `error`) when neither is set.
[[nodiscard]] std::string default_socket_dir(std::string& error);

// Where SlimeVR's OpenVR driver finds bodyd from inside SteamVR's pressure-vessel container,
// whose $XDG_RUNTIME_DIR is not the user's: $XDG_DATA_HOME/dev.slimevr.SlimeVR (or
// ~/.local/share/dev.slimevr.SlimeVR). The driver (BridgeTransport.hpp, GetBridgePath) takes
// the first of $XDG_RUNTIME_DIR/SlimeVRDriver, $XDG_DATA_HOME/dev.slimevr.SlimeVR/SlimeVRDriver,
// ~/.local/share/dev.slimevr.SlimeVR/SlimeVRDriver that exists, so this place works both inside
// the container and outside it. Empty (and `error`) when neither XDG_DATA_HOME nor HOME is set.
[[nodiscard]] std::string default_driver_socket_dir(std::string& error);

// Logs a warning when $XDG_RUNTIME_DIR/SlimeVRDriver exists and is not `path`: the driver picks
// the first of its places that exists (not one that accepts), so a stale socket file there (or
// a SlimeVR server) keeps it from bodyd's socket.
void warn_if_shadowed(const std::string& path);

// A spec's socket path: `argument` (a path; "~/" is the home directory), or
// `default_dir`/`name` when empty. Empty and `error` when it cannot be made.
[[nodiscard]] std::string socket_path(std::string_view argument, std::string_view name, std::string& error,
                                      std::string (*default_dir)(std::string&) = default_socket_dir);

// Makes a listening, non-blocking Unix socket at `path`: its directory made (0700) or checked to
// be private, a stale socket file of a process that is gone replaced, a live one refused, the
// socket file 0600. The fd, or -1 and `error` (what is wrong and what to do).
[[nodiscard]] int listen_unix(const std::string& path, std::string& error);
// Sets SO_SNDBUF (a client that does not read fills it soon and is then noticed).
void limit_send_buffer(int fd, int bytes);

// ---- the server ---------------------------------------------------------------------------------

inline constexpr std::size_t kMaxConnections = 4;
inline constexpr std::size_t kMaxPendingOutBytes = 64 * 1024;  // a client that reads nothing is dropped past this
inline constexpr int kSendBufferBytes = 16 * 1024;              // SO_SNDBUF of each connection
// The driver sends a Position per device on every turn of its 2 ms loop (444-473 Hz measured)
// and a Battery per device every 100 ms: 8 devices are about 4,100 frames a second. A client
// sending more than 5 times that is no driver: dropped as a flood.
inline constexpr std::uint32_t kMaxFramesPerSecond = 20000;
// What the server answers a Version with: the driver's own PROTOCOL_VERSION
// (src/bridge/BridgeClient.hpp at dcc0f56). The server never sends a Version unasked.
inline constexpr std::int32_t kProtocolVersion = 2;
// Samples of one device reach the reconstruction at most this often; the ones in between are
// coalesced to the newest (forwarded when its turn comes): the driver's 470 Hz would otherwise
// queue up behind the reconstruction (tens of milliseconds late) and cost a core.
inline constexpr double kMaxForwardHz = 100.0;
// The virtual trackers turn OCCLUDED when no pose with a tracked headset was published for this
// long (the headset lost, or its samples stopped), and their status is sent again every
// kStatusRepeatNs (the driver drops a status that arrives before SteamVR activated the tracker).
inline constexpr std::int64_t kTrackersLostAfterNs = 60'000'000;
inline constexpr std::int64_t kStatusRepeatNs = 1'000'000'000;
// A connection's TrackerAdded lines in the log (and its devices in the statistics) stop here;
// more are counted (`devices_not_listed`).
inline constexpr std::size_t kMaxDevicesListed = 32;

// A virtual tracker the server announces to each driver (steamvr output).
struct AnnouncedTracker {
  std::int32_t id = 0;
  std::string serial;  // stable: "bodyd-waist"
  std::string name;    // "bodyd waist"
  std::int32_t role = 0;
};

struct TrackerPoseOut {
  std::int32_t id = 0;
  Vec3 position_m = Vec3::Zero();  // the driver's space
  Quat rotation = Quat::Identity();
};

struct BridgeStats {
  std::string path;
  bool listening = false;
  std::size_t clients = 0;
  std::uint64_t connections = 0;   // accepted since start
  std::uint64_t disconnects = 0;   // closed by the client
  std::uint64_t dropped = 0;       // closed by bodyd (bad input, flood, slow reader)
  std::uint64_t refused = 0;       // more than kMaxConnections at once
  std::uint64_t frames_in = 0;
  std::uint64_t samples = 0;       // pushed to the sink
  double rate_hz = 0.0;            // samples pushed per second (the last full second)
  std::uint64_t coalesced = 0;     // superseded by a newer sample of the same device before their turn
  std::uint64_t untrusted = 0;     // positions not used: data_source IMU, no x, y, z, or the device's status not OK
  std::uint64_t devices_not_listed = 0;  // TrackerAdded beyond kMaxDevicesListed on one connection
  std::uint64_t statuses_out = 0;  // TrackerStatus sent for the virtual trackers
  bool trackers_tracked = false;   // the virtual trackers' status is OK (else OCCLUDED)
  std::uint64_t ignored = 0;       // well-formed and not used (other roles, battery, user actions, no sink)
  std::uint64_t frames_out = 0;
  std::uint64_t publishes = 0;
  std::uint64_t publishes_without_client = 0;  // nobody connected: nothing to send (not a failure)
  std::uint64_t rejected = 0;
  std::map<std::string, std::uint64_t> rejected_by_reason;
  // tracker serial -> role of the devices that announced themselves on the open connections
  // (at most kMaxDevicesListed per connection), and what bodyd does with each.
  std::map<std::string, std::int32_t> roles_in;
  std::map<std::string, std::string> roles_use;  // serial -> "head", "left_hand", "hips", ..., or "not used"
  std::string last_error;
};

class BridgeServer : NonCopyable {
 public:
  explicit BridgeServer(std::string path);
  ~BridgeServer();

  [[nodiscard]] const std::string& path() const { return path_; }
  // Binds, listens and starts the thread on the first call; later calls only count users.
  // Empty, or what is wrong and what to do.
  [[nodiscard]] std::string start();
  // Undoes one start(); the last closes the socket, removes its file and joins the thread.
  void stop();

  // The source side: samples of the announced headset, controllers and body trackers go to
  // `sink` (nullptr: nowhere).
  void attach_sink(SampleSink* sink, std::uint16_t source_index);

  // The source index of the source attached (attach_sink), nullopt when none is: which samples
  // came from this socket's driver (the steamvr output leaves out the trackers SteamVR has).
  [[nodiscard]] std::optional<std::uint16_t> source_index() const;

  // The output side: announced (TrackerAdded, TrackerStatus OK) to every connection now and to
  // each new one, except those left out (set_left_out).
  void set_trackers(std::vector<AnnouncedTracker> trackers);
  // The trackers (by id) the runtime already has real ones for: not announced to a connection
  // that was not announced them yet, reported OCCLUDED (and sent no Position) on one that was;
  // a tracker no longer left out is announced where it was not and reported as the others.
  // Takes effect at once on every connection.
  void set_left_out(std::vector<std::int32_t> ids);
  // One Position per pose and tracker (the trackers announced on that connection and not left
  // out) to every connection when `tracked` (the pose's headset is tracked); otherwise the
  // trackers are reported OCCLUDED and no Position is sent (the driver would mark them valid
  // again). Never blocks. False (and `out_error`) when a connection had to be dropped; no client
  // connected is not a failure (counted).
  [[nodiscard]] bool publish(const TrackerPoseOut* poses, std::size_t count, bool tracked, std::string& out_error);

  [[nodiscard]] BridgeStats stats() const;

 private:
  struct Impl;
  std::string path_;
  std::unique_ptr<Impl> impl_;
};

// The server of `path`, shared by every user of the same path in this process (a registry
// keyed by the path; the server lives while someone holds it).
[[nodiscard]] std::shared_ptr<BridgeServer> shared_bridge(const std::string& path);

}  // namespace bodyd::drivers::slimevr
