// The SlimeVR bridge server, its registry and the steamvr:/monado: sources (slimevr_bridge.h).
#include "bodyd/drivers/slimevr_bridge.h"
#include "bodyd/drivers/framed_server.h"
#include "bodyd/drivers/open_source.h"

#include "bodyd/paths/private_dir.h"

#include "bodyd/motion/limits.h"

#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>

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

// Which of bodyd's roles a SlimeVR role feeds (the headset and the two controllers).
std::optional<Role> bodyd_role(std::int32_t r) {
  if (r == role::kHmd) return Role::Head;
  if (r == role::kLeftController) return Role::LeftHand;
  if (r == role::kRightController) return Role::RightHand;
  return std::nullopt;
}

// Logs the 1st, 2nd, 4th, 8th... occurrence of each reason.
bool log_now(std::uint64_t count) { return count != 0 && (count & (count - 1)) == 0; }

}  // namespace

std::string default_socket_dir(std::string& error) {
  if (std::string d = env("XDG_RUNTIME_DIR"); !d.empty()) return d;
  if (std::string d = env("XDG_DATA_HOME"); !d.empty()) return d + "/dev.slimevr.SlimeVR";
  if (std::string h = env("HOME"); !h.empty()) return h + "/.local/share/dev.slimevr.SlimeVR";
  error = "neither XDG_RUNTIME_DIR, XDG_DATA_HOME nor HOME is set: name the socket path in the spec";
  return {};
}

std::string socket_path(std::string_view argument, std::string_view name, std::string& error) {
  std::string path(argument);
  if (path.empty()) {
    const std::string dir = default_socket_dir(error);
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
    std::string serial;
    std::int32_t role = 0;
    std::optional<Role> bodyd;
  };
  struct Connection final : FramedConnection {
    std::map<std::int32_t, Device> devices;  // by tracker_id
  };

  explicit Impl(std::string p) : path(std::move(p)), server(path, FramedServerLimits{}, *this) { stats.path = path; }
  ~Impl() override { server.stop(); }

  std::string path;
  FramedServer server;       // its mutex() guards everything below
  int users = 0;
  SampleSink* sink = nullptr;
  std::uint16_t source_index = 0;
  std::vector<AnnouncedTracker> trackers;
  Encoder encoder;
  BridgeStats stats;

  std::mutex& mutex() const { return server.mutex(); }

  void reject(const std::string& reason, const std::string& detail) {
    ++stats.rejected;
    const std::uint64_t n = ++stats.rejected_by_reason[reason];
    stats.last_error = reason + ": " + detail;
    if (log_now(n))
      spdlog::warn("bridge {}: {} ({}; {} so far, logged at the 1st, 2nd, 4th, 8th...)", path, detail, reason, n);
  }

  void announce(FramedConnection& c) {
    encoder.version(c.out, kProtocolVersion);
    for (const AnnouncedTracker& t : trackers) {
      encoder.tracker_added(c.out, t.id, t.serial, t.name, t.role, "bodyd");
      encoder.tracker_status(c.out, t.id, status::kOk);
    }
  }

  void push_invalid(const Connection& c) {
    if (sink == nullptr) return;
    for (const auto& [id, d] : c.devices) {
      if (!d.bodyd) continue;
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
                            " frames in a second: the connection is dropped");
        ++stats.dropped;
        return;
      case FramedDrop::SlowReader:
        reject("slow_reader", "client " + std::to_string(c->number) + " read nothing of " + std::to_string(bytes) +
                                  " bytes waiting: the connection is dropped");
        ++stats.dropped;
        return;
      case FramedDrop::TooManyClients:
        ++stats.refused;
        reject("too_many_clients", "more than " + std::to_string(kMaxConnections) + " clients at once: refused");
        return;
    }
  }

  void closing(FramedConnection& c, std::size_t remaining, bool stopping) override {
    push_invalid(static_cast<Connection&>(c));
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

  void handle(Connection& c, const Message& m, std::int64_t arrival_ns) {
    switch (m.kind) {
      case Message::Kind::TrackerAdded: {
        if (m.role < 0 || m.role > role::kMax) {
          reject("unknown_role", "TrackerAdded " + std::to_string(m.tracker_id) + " \"" + m.serial + "\" has role " +
                                     std::to_string(m.role) + " (SlimeVR's roles are 0-21)");
          return;
        }
        Device& d = c.devices[m.tracker_id];
        d.serial = m.serial;
        d.role = m.role;
        d.bodyd = bodyd_role(m.role);
        stats.roles_in[m.serial.empty() ? std::to_string(m.tracker_id) : m.serial] = m.role;
        if (!d.bodyd) ++stats.ignored;
        spdlog::info("bridge {}: device {} \"{}\" ({}), role {}{}", path, m.tracker_id, m.serial, m.name, m.role,
                     d.bodyd ? std::string(" -> ") + std::string(role_name(*d.bodyd)) : std::string(" (not used)"));
        return;
      }
      case Message::Kind::Position: {
        const auto it = c.devices.find(m.tracker_id);
        if (it == c.devices.end()) {
          reject("unknown_tracker", "Position for tracker " + std::to_string(m.tracker_id) + ", which no TrackerAdded announced");
          return;
        }
        if (!it->second.bodyd || sink == nullptr) {
          ++stats.ignored;
          return;
        }
        if (!m.has_position) {
          ++stats.ignored;  // rotation only (IMU): the reconstruction needs positions
          return;
        }
        const Vec3 p(m.x, m.y, m.z);
        const Quat q(m.qw, m.qx, m.qy, m.qz);
        const double norm = std::sqrt(q.coeffs().squaredNorm());
        if (!limits::position_plausible(p.x()) || !limits::position_plausible(p.y()) ||
            !limits::position_plausible(p.z()) || !std::isfinite(norm) ||
            std::fabs(norm - 1.0) > limits::kQuatNormTolerance) {
          reject("bad_pose", "Position of tracker " + std::to_string(m.tracker_id) + " is not a pose (position (" +
                                 std::to_string(m.x) + ", " + std::to_string(m.y) + ", " + std::to_string(m.z) +
                                 ") m, quaternion norm " + std::to_string(norm) + ")");
          return;
        }
        SourceSample s;
        s.sample.t_ns = arrival_ns;
        s.sample.role = *it->second.bodyd;
        s.sample.valid = true;
        s.sample.position_m = p;
        s.sample.rotation = q.normalized();
        s.sample.frame = PoseFrame::Device;
        s.arrival_ns = arrival_ns;
        s.source_index = source_index;
        sink->push(s);
        ++stats.samples;
        return;
      }
      case Message::Kind::TrackerStatus: {
        const auto it = c.devices.find(m.tracker_id);
        if (it != c.devices.end() && it->second.bodyd && sink != nullptr && m.status == status::kDisconnected) {
          SourceSample s;
          s.sample.t_ns = arrival_ns;
          s.sample.role = *it->second.bodyd;
          s.sample.frame = PoseFrame::Device;
          s.arrival_ns = arrival_ns;
          s.source_index = source_index;
          sink->push(s);
        } else {
          ++stats.ignored;
        }
        return;
      }
      case Message::Kind::Version:
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
    for (const AnnouncedTracker& t : impl_->trackers) {
      impl_->encoder.tracker_added(c->out, t.id, t.serial, t.name, t.role, "bodyd");
      impl_->encoder.tracker_status(c->out, t.id, status::kOk);
    }
    impl_->server.flush(*c);
  }
  impl_->server.wake();
}

bool BridgeServer::publish(const TrackerPoseOut* poses, std::size_t count, std::string& out_error) {
  std::lock_guard lock(impl_->mutex());
  ++impl_->stats.publishes;
  bool dropped = false, any = false;
  for (const auto& c : impl_->server.connections()) {
    if (c->drop) continue;
    any = true;
    for (std::size_t i = 0; i < count; ++i) impl_->encoder.position(c->out, poses[i].id, poses[i].position_m, poses[i].rotation);
    impl_->stats.frames_out += count;
    impl_->server.flush(*c);
    dropped |= c->drop;
  }
  if (dropped) impl_->server.wake();
  if (!any) ++impl_->stats.publishes_without_client;
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
  return s;
}

std::shared_ptr<BridgeServer> shared_bridge(const std::string& path) {
  static std::mutex mutex;
  static std::map<std::string, std::weak_ptr<BridgeServer>> servers;
  std::lock_guard lock(mutex);
  std::error_code ec;
  const std::string key = std::filesystem::absolute(path, ec).lexically_normal().string();
  if (auto s = servers[key].lock()) return s;
  auto s = std::make_shared<BridgeServer>(path);
  servers[key] = s;
  return s;
}

// ---- the sources -------------------------------------------------------------------------------

namespace {

class BridgeSource final : public TrackerSource {
 public:
  BridgeSource(std::string name, std::shared_ptr<BridgeServer> server) : name_(std::move(name)), server_(std::move(server)) {}
  ~BridgeSource() override { stop(); }

  const std::string& name() const override { return name_; }

  std::string start(SampleSink& sink, std::uint16_t source_index) override {
    if (started_) return {};
    server_->attach_sink(&sink, source_index);
    if (std::string e = server_->start(); !e.empty()) {
      server_->attach_sink(nullptr, 0);
      return "--source " + name_ + ": " + e;
    }
    started_ = true;
    return {};
  }

  void stop() override {
    if (!started_) return;
    server_->attach_sink(nullptr, 0);
    server_->stop();
    started_ = false;
  }

  SourceStatus status() const override {
    const BridgeStats b = server_->stats();
    SourceStatus s;
    s.name = name_;
    s.connected = b.clients > 0;
    s.samples = b.samples;
    s.rejected = b.rejected;
    s.rejected_by_reason = b.rejected_by_reason;
    s.last_error = b.last_error;
    s.counters = {{"clients", b.clients},         {"connections", b.connections}, {"disconnects", b.disconnects},
                  {"dropped", b.dropped},         {"frames_in", b.frames_in},     {"ignored", b.ignored},
                  {"refused", b.refused}};
    return s;
  }

 private:
  std::string name_;
  std::shared_ptr<BridgeServer> server_;
  bool started_ = false;
};

}  // namespace

std::unique_ptr<TrackerSource> open_steamvr_source(std::string_view spec, std::string_view argument, std::string& error) {
  std::string e;
  const std::string path = socket_path(argument, kDriverSocketName, e);
  if (path.empty()) {
    error = "--source " + std::string(spec) + ": " + e;
    return nullptr;
  }
  return std::make_unique<BridgeSource>("steamvr:" + path, shared_bridge(path));
}

std::unique_ptr<TrackerSource> open_monado_source(std::string_view spec, std::string_view argument, std::string& error) {
  std::string e;
  std::string dir(argument);
  if (dir.empty()) dir = default_socket_dir(e);
  std::string path = dir.empty() ? std::string() : socket_path(dir + "/" + std::string(kMonadoInputSocketName), {}, e);
  if (path.empty()) {
    error = "--source " + std::string(spec) + ": " + e;
    return nullptr;
  }
  return std::make_unique<BridgeSource>("monado:" + path, shared_bridge(path));
}

}  // namespace bodyd::drivers::slimevr

namespace bodyd::drivers {

// The registry's factories (sources.cpp): steamvr[:SOCKET] and monado[:DIR].
std::unique_ptr<TrackerSource> open_steamvr_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  return slimevr::open_steamvr_source(spec.text, spec.argument, error);
}
std::unique_ptr<TrackerSource> open_monado_spec(const SourceSpec& spec, const SourceOptions&, std::string& error) {
  return slimevr::open_monado_source(spec.text, spec.argument, error);
}

}  // namespace bodyd::drivers
