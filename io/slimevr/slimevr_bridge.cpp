// The SlimeVR bridge server (slimevr_bridge.h); its registry is bridge_registry.cpp, its sources
// bridge_source.cpp (steamvr:) and ../solarxr/monado_source.cpp (monado:).
#include "bodyd/io/slimevr/slimevr_bridge.h"
#include "bodyd/io/slimevr/framed_server.h"
#include "bodyd/io/open_source.h"
#include "bridge_source.h"

#include "bodyd/base/log_rate.h"
#include "bodyd/paths/private_dir.h"

#include "bodyd/motion/limits.h"
#include "bodyd/motion/printable.h"

#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <set>

namespace bodyd::drivers::slimevr {

namespace {

std::string env(const char* name) {
  const char* v = std::getenv(name);
  return v ? std::string(v) : std::string();
}

// A directory a socket may live in: a directory (not a symlink), owned by this user, with no
// access for others. Empty, or why not.
std::string check_private_dir(const std::filesystem::path& dir) {
  const std::string problem = paths::private_directory_problem(dir);
  if (problem.empty() || problem.find(" (mode ") == std::string::npos) return problem;
  return problem + ": bodyd puts the bridge socket only in a private directory (mode 0700, owned by you); fix it "
                   "(chmod 700 " + dir.string() + ") or name another socket path";
}

// Makes `dir` (0700 for what it creates) and checks that it is private.
std::string prepare_dir(const std::filesystem::path& dir) {
  struct stat st {};
  if (::lstat(dir.c_str(), &st) != 0 && errno == ENOENT) {
    std::error_code ec;
    if (dir.has_parent_path()) std::filesystem::create_directories(dir.parent_path(), ec);
    if (ec) return "cannot create directory " + dir.parent_path().string() + ": " + ec.message();
    if (::mkdir(dir.c_str(), 0700) != 0 && errno != EEXIST)
      return "cannot create directory " + dir.string() + ": " + std::strerror(errno);
  }
  return check_private_dir(dir);
}

std::int64_t now_ns() { return monotonic_ns(); }

// Which of bodyd's roles a SlimeVR role feeds: the headset; the controllers, which the driver
// announces as LEFT_HAND / RIGHT_HAND (11 / 12, from Prop_ControllerRoleHint_Int32:
// VRDriver.cpp, GetRoleForDevice) and other clients as LEFT_CONTROLLER / RIGHT_CONTROLLER; and
// the body trackers, which the driver announces with the role their Prop_ControllerType_String
// names (vive_tracker_waist 1, ...). Shoulders, SlimeVR's HEAD (not the headset), neck and the
// others have no bodyd role: not used.
std::optional<Role> bodyd_role(std::int32_t r) {
  switch (r) {
    case role::kHmd: return Role::Head;
    case role::kLeftHand:
    case role::kLeftController: return Role::LeftHand;
    case role::kRightHand:
    case role::kRightController: return Role::RightHand;
    case role::kWaist: return Role::Hips;
    case role::kChest: return Role::Chest;
    case role::kLeftFoot: return Role::LeftFoot;
    case role::kRightFoot: return Role::RightFoot;
    case role::kLeftKnee: return Role::LeftKnee;
    case role::kRightKnee: return Role::RightKnee;
    case role::kLeftElbow: return Role::LeftElbow;
    case role::kRightElbow: return Role::RightElbow;
    default: return std::nullopt;
  }
}

constexpr std::int64_t kForwardIntervalNs = static_cast<std::int64_t>(1e9 / kMaxForwardHz);

}  // namespace

// SlimeVR's role names (the driver's TrackerRole.hpp), for status and logs.
std::string role_label(std::int32_t r) {
  static constexpr std::array<std::string_view, role::kMax + 1> kNames{
      "none",       "waist",         "left_foot",      "right_foot", "chest",          "left_knee",
      "right_knee", "left_elbow",    "right_elbow",    "left_shoulder", "right_shoulder", "left_hand",
      "right_hand", "left_controller", "right_controller", "head",   "neck",           "camera",
      "keyboard",   "hmd",           "beacon",         "generic_controller"};
  return r >= 0 && r <= role::kMax ? std::string(kNames[static_cast<std::size_t>(r)]) : std::to_string(r);
}

std::string default_driver_socket_dir(std::string& error) {
  if (std::string d = env("XDG_DATA_HOME"); !d.empty()) return d + "/dev.slimevr.SlimeVR";
  if (std::string h = env("HOME"); !h.empty()) return h + "/.local/share/dev.slimevr.SlimeVR";
  error = "neither XDG_DATA_HOME nor HOME is set: name the socket path in the spec";
  return {};
}

void warn_if_shadowed(const std::string& path) {
  const std::string runtime = env("XDG_RUNTIME_DIR");
  if (runtime.empty()) return;
  const std::string first = runtime + "/" + std::string(kDriverSocketName);
  std::error_code ec;
  if (first == path || !std::filesystem::exists(std::filesystem::symlink_status(first, ec))) return;
  spdlog::warn("bridge: {} exists (a SlimeVR server, or one that is gone?): SlimeVR's driver outside SteamVR's "
               "container connects to the first of its places that exists, so it may never reach bodyd on {}; "
               "stop that server or remove the file if nothing listens on it",
               printable(first, 200), printable(path, 200));
}

std::string default_socket_dir(std::string& error) {
  if (std::string d = env("XDG_RUNTIME_DIR"); !d.empty()) return d;
  if (std::string d = default_driver_socket_dir(error); !d.empty()) return d;
  error = "neither XDG_RUNTIME_DIR, XDG_DATA_HOME nor HOME is set: name the socket path in the spec";
  return {};
}

std::string socket_path(std::string_view argument, std::string_view name, std::string& error,
                        std::string (*default_dir)(std::string&)) {
  std::string path(argument);
  if (path.empty()) {
    const std::string dir = default_dir(error);
    if (dir.empty()) return {};
    path = dir + "/" + std::string(name);
  } else if (path.rfind("~/", 0) == 0) {
    const std::string home = env("HOME");
    if (home.empty()) {
      error = "\"" + path + "\": HOME is not set";
      return {};
    }
    path = home + path.substr(1);
  }
  if (path.size() >= sizeof(sockaddr_un::sun_path)) {
    error = "socket path " + path + " is too long for a Unix socket (at most " +
            std::to_string(sizeof(sockaddr_un::sun_path) - 1) + " bytes)";
    return {};
  }
  return path;
}

int listen_unix(const std::string& path, std::string& error) {
  const std::filesystem::path p(path);
  if (std::string e = prepare_dir(p.parent_path().empty() ? std::filesystem::path(".") : p.parent_path()); !e.empty()) {
    error = e;
    return -1;
  }
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.size() >= sizeof(addr.sun_path)) {
    error = "path too long for a Unix socket";
    return -1;
  }
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode)) {
      error = "exists and is not a socket; bodyd does not replace other files (remove it, or name another path)";
      return -1;
    }
    const int probe = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const bool live = probe >= 0 && ::connect(probe, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
    if (probe >= 0) ::close(probe);
    if (live) {
      error = "in use: another program listens on it (a SlimeVR server, or another bodyd?); stop it, or name another path";
      return -1;
    }
    ::unlink(path.c_str());  // stale, from a process that is gone
  }
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    error = std::string("socket: ") + std::strerror(errno);
    return -1;
  }
  // Mode 0600 from the start (the directory keeps others out in any case).
  const mode_t old_mask = ::umask(0177);
  const int bound = ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
  ::umask(old_mask);
  if (bound != 0 || ::listen(fd, 8) != 0) {
    error = std::string(bound != 0 ? "bind: " : "listen: ") + std::strerror(errno);
    ::close(fd);
    return -1;
  }
  return fd;
}

void limit_send_buffer(int fd, int bytes) { (void)::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &bytes, sizeof bytes); }

// ---- the server ---------------------------------------------------------------------------------

// The socket loop is FramedServer's (framed_server.h); what the bridge does with each event is here.
struct BridgeServer::Impl final : FramedHandler {
  struct Device {           // a tracker a client announced
    std::string serial;     // the stats' key ("" when not listed)
    std::int32_t role = 0;
    std::optional<Role> wanted;  // the role it announces (bodyd_role)
    std::optional<Role> bodyd;   // the role it feeds: `wanted` while this device owns it
    bool status_ok = true;      // its last TrackerStatus was OK (none yet counts as OK)
    std::int32_t status = status::kOk;  // its last TrackerStatus
    bool imu_only = false;      // its last Position had data_source IMU
    bool last_valid = false;    // the last sample forwarded (or held) was valid
    std::int64_t last_forward_ns = INT64_MIN;
    std::optional<SourceSample> held;  // the newest sample waiting for its turn
  };
  struct Connection final : FramedConnection {
    std::map<std::int32_t, Device> devices;  // by tracker_id
    std::size_t listed = 0;                  // devices in the stats and the log (kMaxDevicesListed)
    bool version_answered = false;
    std::set<std::int32_t> announced;        // the virtual trackers (ids) a TrackerAdded was sent for
  };

  explicit Impl(std::string p) : path(std::move(p)), server(path, FramedServerLimits{}, *this) { stats.path = path; }
  ~Impl() override { server.stop(); }

  std::string path;
  FramedServer server;       // its mutex() guards everything below
  int users = 0;
  SampleSink* sink = nullptr;
  std::uint16_t source_index = 0;
  std::vector<AnnouncedTracker> trackers;
  std::set<std::int32_t> left_out;  // trackers the runtime has real ones for (set_left_out)
  Encoder encoder;
  BridgeStats stats;
  RateMeter rate;  // samples forwarded to the sink
  // Which connection (its number) and device own each of bodyd's roles: the first to announce
  // one keeps it until its connection closes (a second headset must not make the body jump).
  std::map<Role, std::pair<std::uint64_t, std::int32_t>> owners;
  std::int64_t last_tracked_publish_ns = INT64_MIN;  // the last publish() with a tracked headset
  std::int64_t last_status_ns = 0;                   // the virtual trackers' status last sent

  std::mutex& mutex() const { return server.mutex(); }

  void reject(const std::string& reason, const std::string& detail) {
    ++stats.rejected;
    const std::uint64_t n = ++stats.rejected_by_reason[reason];
    stats.last_error = reason + ": " + detail;
    if (log_occurrence(n))
      spdlog::warn("bridge {}: {} ({}; {} so far, logged at the 1st, 2nd, 4th, 8th...)", path, detail, reason, n);
  }

  // The status of the virtual trackers announced on one connection: OK while they have a body
  // and are not left out, else OCCLUDED.
  void send_status(FramedConnection& fc) {
    auto& c = static_cast<Connection&>(fc);
    for (const AnnouncedTracker& t : trackers) {
      if (!c.announced.count(t.id)) continue;
      const bool ok = stats.trackers_tracked && !left_out.count(t.id);
      encoder.tracker_status(c.out, t.id, ok ? status::kOk : status::kOccluded);
      ++stats.statuses_out;
    }
  }
  void send_status_to_all(std::int64_t now) {
    for (const auto& c : server.connections())
      if (!c->drop) send_status(*c);
    last_status_ns = now;
  }

  // TrackerAdded for each virtual tracker not announced on this connection yet and not left
  // out, then the status of every one announced. No Version: the driver sends its own and this
  // server answers it.
  void announce(FramedConnection& fc) {
    auto& c = static_cast<Connection&>(fc);
    for (const AnnouncedTracker& t : trackers)
      if (!left_out.count(t.id) && c.announced.insert(t.id).second)
        encoder.tracker_added(c.out, t.id, t.serial, t.name, t.role, "bodyd");
    send_status(c);
  }

  void push_invalid(const Connection& c) {
    if (sink == nullptr) return;
    for (const auto& [id, d] : c.devices) {
      if (!d.bodyd) continue;  // only roles this connection owns
      SourceSample s;
      s.sample.t_ns = now_ns();
      s.sample.role = *d.bodyd;
      s.sample.valid = false;
      s.sample.frame = PoseFrame::Device;
      s.arrival_ns = s.sample.t_ns;
      s.source_index = source_index;
      sink->push(s);
    }
  }

  // A device's sample toward the reconstruction: at once when its turn has come (or when it
  // changes between valid and lost, which must be seen at once), else held as the newest.
  void forward(Connection& c, Device& d, const SourceSample& s) {
    if (sink == nullptr) return;
    const bool change = s.sample.valid != d.last_valid;
    d.last_valid = s.sample.valid;
    if (change || d.last_forward_ns == INT64_MIN || s.arrival_ns - d.last_forward_ns >= kForwardIntervalNs) {
      if (d.held) ++stats.coalesced;
      d.held.reset();
      // A headset sample makes a pose: the other devices' newest samples go first, so the pose
      // has hands at most one driver loop older than the headset (held, they lagged up to 10 ms).
      if (d.bodyd == Role::Head)
        for (auto& [id, other] : c.devices)
          if (&other != &d && other.held) {
            other.last_forward_ns = s.arrival_ns;
            sink->push(*other.held);
            ++stats.samples;
            rate.count(s.arrival_ns);
            other.held.reset();
          }
      d.last_forward_ns = s.arrival_ns;
      sink->push(s);
      ++stats.samples;
      rate.count(s.arrival_ns);
      return;
    }
    if (d.held) ++stats.coalesced;
    d.held = s;
  }

  SourceSample sample_of(const Device& d, std::int64_t arrival_ns) const {
    SourceSample s;
    s.sample.t_ns = arrival_ns;
    s.sample.role = *d.bodyd;
    s.sample.frame = PoseFrame::Device;
    s.arrival_ns = arrival_ns;
    s.source_index = source_index;
    return s;
  }

  void forget_devices(Connection& c) {
    std::vector<Role> released;
    for (auto it = owners.begin(); it != owners.end();) {
      if (it->second.first != c.number) {
        ++it;
        continue;
      }
      released.push_back(it->first);
      it = owners.erase(it);
    }
    // A device of another open connection that announced a released role takes it over.
    for (Role r : released) {
      for (const auto& other : server.connections()) {
        if (other.get() == &c || other->drop) continue;
        auto& oc = static_cast<Connection&>(*other);
        for (auto& [id, d] : oc.devices) {
          if (d.wanted != r || d.bodyd || owners.count(r)) continue;
          owners.emplace(r, std::pair{oc.number, id});
          d.bodyd = r;
          if (stats.roles_use.count(d.serial)) stats.roles_use[d.serial] = std::string(role_name(r));
          spdlog::info("bridge {}: client {}'s device {} now feeds the {} (client {} left)", path, oc.number, id,
                       role_name(r), c.number);
        }
      }
    }
    for (const auto& [id, d] : c.devices) {
      if (d.serial.empty()) continue;
      stats.roles_in.erase(d.serial);
      stats.roles_use.erase(d.serial);
    }
  }

  // ---- FramedHandler ----

  std::unique_ptr<FramedConnection> make_connection() override { return std::make_unique<Connection>(); }

  void accepted(FramedConnection& c) override {
    ++stats.connections;
    announce(c);
    server.flush(c);
    spdlog::info("bridge {}: client {} connected ({} now)", path, c.number, server.connections().size() + 1);
  }

  void disconnected(FramedConnection&) override { ++stats.disconnects; }

  void dropping(FramedConnection* c, FramedDrop why, std::size_t bytes) override {
    switch (why) {
      case FramedDrop::FrameTooLong:
      case FramedDrop::FrameTooShort:
        reject(why == FramedDrop::FrameTooLong ? "frame_too_long" : "frame_too_short",
               "a frame declares " + std::to_string(bytes) + " bytes (the protocol allows 4 to " +
                   std::to_string(kMaxFrameBytes) + "): the stream cannot be followed, the connection is dropped");
        ++stats.dropped;
        return;
      case FramedDrop::Flood:
        reject("flood", "client " + std::to_string(c->number) + " sent more than " + std::to_string(kMaxFramesPerSecond) +
                            " frames in a second (a driver with 8 devices sends about 4,100): the connection is dropped");
        ++stats.dropped;
        return;
      case FramedDrop::SlowReader:
        reject("slow_reader", "client " + std::to_string(c->number) + " read nothing of " + std::to_string(bytes) +
                                  " bytes waiting: the connection is dropped");
        ++stats.dropped;
        return;
      case FramedDrop::TooManyClients:
        ++stats.refused;
        reject("too_many_clients", "more than " + std::to_string(kMaxConnections) +
                                       " clients at once, none idle for 2 s: refused");
        return;
      case FramedDrop::IdleEvicted:
        ++stats.dropped;
        reject("idle_evicted", "client " + std::to_string(c->number) + " sent nothing for " + std::to_string(bytes) +
                                   " s while a new client waited for one of the " + std::to_string(kMaxConnections) +
                                   " places: it is dropped");
        return;
      case FramedDrop::OutOfDescriptors:
        reject("out_of_descriptors", std::string("cannot accept a client: ") + std::strerror(static_cast<int>(bytes)) +
                                         " (ulimit -n): accepting pauses 100 ms; raise the limit if this is not an attack");
        return;
    }
  }

  void closing(FramedConnection& c, std::size_t remaining, bool stopping) override {
    auto& conn = static_cast<Connection&>(c);
    push_invalid(conn);
    forget_devices(conn);
    if (!stopping) spdlog::info("bridge {}: client {} left ({} now)", path, c.number, remaining);
  }

  void frame(FramedConnection& c, const std::uint8_t* payload, std::size_t size, std::int64_t arrival_ns) override {
    Message m;
    std::string error;
    if (!decode_message(payload, size, m, error)) {
      reject("malformed", error);  // the framing held: skip this frame only
      return;
    }
    handle(static_cast<Connection&>(c), m, arrival_ns);
  }

  int tick(std::int64_t now) override {
    std::int64_t wait_ns = 100'000'000;
    for (const auto& cp : server.connections()) {
      auto& c = static_cast<Connection&>(*cp);
      for (auto& [id, d] : c.devices) {
        if (!d.held) continue;
        const std::int64_t due = d.last_forward_ns + kForwardIntervalNs;
        if (now >= due) {
          d.last_forward_ns = now;
          if (sink != nullptr) {
            sink->push(*d.held);
            ++stats.samples;
            rate.count(now);
          }
          d.held.reset();
        } else {
          wait_ns = std::min(wait_ns, due - now);
        }
      }
    }
    if (!trackers.empty()) {
      if (stats.trackers_tracked && now - last_tracked_publish_ns > kTrackersLostAfterNs) {
        stats.trackers_tracked = false;
        send_status_to_all(now);
      } else if (now - last_status_ns >= kStatusRepeatNs) {
        send_status_to_all(now);
      }
      if (stats.trackers_tracked) wait_ns = std::min(wait_ns, last_tracked_publish_ns + kTrackersLostAfterNs + 1 - now);
      wait_ns = std::min(wait_ns, last_status_ns + kStatusRepeatNs - now);
    }
    return static_cast<int>(std::clamp<std::int64_t>((wait_ns + 999'999) / 1'000'000, 0, 100));
  }

  void tracker_added(Connection& c, const Message& m) {
    if (m.role < 0 || m.role > role::kMax) {
      reject("unknown_role", "TrackerAdded " + std::to_string(m.tracker_id) + " \"" + printable(m.serial) +
                                 "\" has role " + std::to_string(m.role) + " (SlimeVR's roles are 0-21)");
      return;
    }
    Device& d = c.devices[m.tracker_id];
    d.role = m.role;
    // One of bodyd's own virtual trackers fed back (a driver that does not skip the trackers it
    // created for this server) is never taken for a real one: it would leave itself out.
    const bool own = std::any_of(trackers.begin(), trackers.end(),
                                 [&](const AnnouncedTracker& t) { return !m.serial.empty() && t.serial == m.serial; });
    d.wanted = own ? std::nullopt : bodyd_role(m.role);
    d.bodyd = d.wanted;
    std::string use = d.bodyd ? std::string(role_name(*d.bodyd))
                              : std::string(own ? "not used (bodyd's own)" : "not used");
    if (d.bodyd) {
      const auto [it, added] = owners.try_emplace(*d.bodyd, c.number, m.tracker_id);
      if (!added && it->second != std::pair{c.number, m.tracker_id}) {
        reject("role_taken", "client " + std::to_string(c.number) + "'s device " + std::to_string(m.tracker_id) +
                                 " \"" + printable(m.serial) + "\" announces the " + use + ", which client " +
                                 std::to_string(it->second.first) + " already has: not used until that one closes");
        use = "not used (the " + use + " of client " + std::to_string(it->second.first) + ")";
        d.bodyd.reset();
      }
    }
    if (!d.bodyd) ++stats.ignored;
    if (d.serial.empty() && c.listed >= kMaxDevicesListed) {
      ++stats.devices_not_listed;
      return;
    }
    if (d.serial.empty()) {
      ++c.listed;
      d.serial = m.serial.empty() ? "#" + std::to_string(c.number) + "." + std::to_string(m.tracker_id)
                                  : printable(m.serial, 64);
      // Another connection's device with the same serial keeps its entry.
      if (stats.roles_in.count(d.serial)) d.serial += " (client " + std::to_string(c.number) + ")";
    }
    stats.roles_in[d.serial] = m.role;
    stats.roles_use[d.serial] = use;
    spdlog::info("bridge {}: device {} \"{}\" ({}), role {} ({}) -> {}", path, m.tracker_id, d.serial,
                 printable(m.name), m.role, role_label(m.role), use);
  }

  void position(Connection& c, const Message& m, std::int64_t arrival_ns) {
    const auto it = c.devices.find(m.tracker_id);
    if (it == c.devices.end()) {
      reject("unknown_tracker", "Position for tracker " + std::to_string(m.tracker_id) + ", which no TrackerAdded announced");
      return;
    }
    Device& d = it->second;
    // Every Position is checked, used or not: a client sending garbage is told so.
    const Vec3 p(m.x, m.y, m.z);
    const Quat q(m.qw, m.qx, m.qy, m.qz);
    const double norm = std::sqrt(q.coeffs().squaredNorm());
    if ((m.has_position && (!limits::position_plausible(p.x()) || !limits::position_plausible(p.y()) ||
                            !limits::position_plausible(p.z()))) ||
        !std::isfinite(norm) || std::fabs(norm - 1.0) > limits::kQuatNormTolerance) {
      reject("bad_pose", "Position of tracker " + std::to_string(m.tracker_id) + " is not a pose (position (" +
                             std::to_string(m.x) + ", " + std::to_string(m.y) + ", " + std::to_string(m.z) +
                             ") m, quaternion norm " + std::to_string(norm) + ")");
      return;
    }
    if (!d.bodyd || sink == nullptr) {
      ++stats.ignored;
      return;
    }
    if (m.has_data_source) d.imu_only = m.data_source == data_source::kImu;
    SourceSample s = sample_of(d, arrival_ns);
    if (!m.has_position || d.imu_only || !d.status_ok) {
      // Rotation only (data_source IMU, no x, y, z), or a status that says the position is not
      // tracked (the driver's OCCLUDED of a device SteamVR tracks by rotation only).
      ++stats.untrusted;
      if (is_xr_role(*d.bodyd) || (!d.status_ok && d.status != status::kOccluded)) {
        // The headset and controllers: the reconstruction treats the position as lost (as a
        // hand out of the cameras' view) until FULL / OK again. Any device whose status is
        // DISCONNECTED, BUSY or ERROR: lost too.
        forward(c, d, s);
        return;
      }
      // A body tracker: its rotation is still observed (TrackerSample::has_position false, as
      // an IMU tracker's), its position not used (docs/conventions.md, "Tracker roles").
      s.sample.valid = true;
      s.sample.has_position = false;
      s.sample.rotation = q.normalized();
      forward(c, d, s);
      return;
    }
    s.sample.valid = true;
    s.sample.position_m = p;
    s.sample.rotation = q.normalized();
    forward(c, d, s);
  }

  void tracker_status(Connection& c, const Message& m, std::int64_t arrival_ns) {
    const auto it = c.devices.find(m.tracker_id);
    if (it == c.devices.end() || !it->second.bodyd || sink == nullptr) {
      ++stats.ignored;
      return;
    }
    Device& d = it->second;
    d.status = m.status;
    d.status_ok = m.status == status::kOk;
    // Lost (disconnected, occluded, busy, in error): seen at once, not at the next Position.
    if (!d.status_ok) forward(c, d, sample_of(d, arrival_ns));
  }

  void handle(Connection& c, const Message& m, std::int64_t arrival_ns) {
    switch (m.kind) {
      case Message::Kind::TrackerAdded: tracker_added(c, m); return;
      case Message::Kind::Position: position(c, m, arrival_ns); return;
      case Message::Kind::TrackerStatus: tracker_status(c, m, arrival_ns); return;
      case Message::Kind::Version:
        if (!c.version_answered) encoder.version(c.out, kProtocolVersion);  // flushed at the end of the round
        else ++stats.ignored;
        c.version_answered = true;
        return;
      case Message::Kind::UserAction:
      case Message::Kind::Battery:
      case Message::Kind::Empty: ++stats.ignored; return;
    }
  }

};

BridgeServer::BridgeServer(std::string path) : path_(std::move(path)), impl_(std::make_unique<Impl>(path_)) {}

BridgeServer::~BridgeServer() {
  {
    std::lock_guard lock(impl_->mutex());
    impl_->users = std::min(impl_->users, 1);
  }
  stop();
}

std::string BridgeServer::start() {
  std::lock_guard lock(impl_->mutex());
  if (impl_->users++ > 0) return {};
  if (std::string e = impl_->server.start(); !e.empty()) {
    impl_->users = 0;
    return "bridge socket " + path_ + ": " + e;
  }
  impl_->stats.listening = true;
  spdlog::info("bridge: listening on {} (SlimeVR driver protocol)", path_);
  return {};
}

void BridgeServer::stop() {
  {
    std::lock_guard lock(impl_->mutex());
    if (impl_->users == 0 || --impl_->users > 0) return;
  }
  impl_->server.stop();
  std::lock_guard lock(impl_->mutex());
  impl_->stats.listening = false;
}

void BridgeServer::attach_sink(SampleSink* sink, std::uint16_t source_index) {
  std::lock_guard lock(impl_->mutex());
  impl_->sink = sink;
  impl_->source_index = source_index;
}

void BridgeServer::set_trackers(std::vector<AnnouncedTracker> trackers) {
  std::lock_guard lock(impl_->mutex());
  impl_->trackers = std::move(trackers);
  for (const auto& c : impl_->server.connections()) {
    impl_->announce(*c);
    impl_->server.flush(*c);
  }
  impl_->server.wake();
}

void BridgeServer::set_left_out(std::vector<std::int32_t> ids) {
  std::lock_guard lock(impl_->mutex());
  std::set<std::int32_t> next(ids.begin(), ids.end());
  if (next == impl_->left_out) return;
  impl_->left_out = std::move(next);
  for (const auto& c : impl_->server.connections()) {
    if (c->drop) continue;
    impl_->announce(*c);
    impl_->server.flush(*c);
  }
  impl_->server.wake();
}

std::optional<std::uint16_t> BridgeServer::source_index() const {
  std::lock_guard lock(impl_->mutex());
  if (impl_->sink == nullptr) return std::nullopt;
  return impl_->source_index;
}

bool BridgeServer::publish(const TrackerPoseOut* poses, std::size_t count, bool tracked, std::string& out_error) {
  std::lock_guard lock(impl_->mutex());
  Impl& im = *impl_;
  ++im.stats.publishes;
  const std::int64_t now = now_ns();
  bool status_change = false;
  if (tracked) {
    im.last_tracked_publish_ns = now;
    status_change = !im.stats.trackers_tracked;
    im.stats.trackers_tracked = true;
  } else if (im.stats.trackers_tracked) {
    status_change = true;
    im.stats.trackers_tracked = false;
  }
  if (status_change) im.last_status_ns = now;
  bool dropped = false, any = false;
  for (const auto& c : im.server.connections()) {
    if (c->drop) continue;
    any = true;
    if (status_change) im.send_status(*c);
    if (tracked) {
      const auto& announced = static_cast<const Impl::Connection&>(*c).announced;
      for (std::size_t i = 0; i < count; ++i) {
        if (im.left_out.count(poses[i].id) || !announced.count(poses[i].id)) continue;
        im.encoder.position(c->out, poses[i].id, poses[i].position_m, poses[i].rotation);
        ++im.stats.frames_out;
      }
    }
    im.server.flush(*c);
    dropped |= c->drop;
  }
  if (status_change) im.server.wake();  // the thread's tick keeps the repeat's clock
  if (dropped) im.server.wake();
  if (!any) ++im.stats.publishes_without_client;
  if (dropped) {
    out_error = "a client that does not read was dropped";
    return false;
  }
  return true;
}

BridgeStats BridgeServer::stats() const {
  std::lock_guard lock(impl_->mutex());
  BridgeStats s = impl_->stats;
  s.clients = impl_->server.connections().size();
  s.frames_in = impl_->server.frames_in();
  s.rate_hz = impl_->rate.rate_hz();
  return s;
}

}  // namespace bodyd::drivers::slimevr
