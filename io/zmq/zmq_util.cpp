#include "bodyd/io/zmq/zmq_util.h"

#include "bodyd/io/zmq/curve_allow.h"
#include "bodyd/io/zmq/endpoint.h"

#include <spdlog/spdlog.h>
#include <zmq.h>

#include <algorithm>
#include <cerrno>
#include <mutex>
#include <set>
#include <cstring>
#include <string_view>

#include <dirent.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

namespace bodyd::daemon {

std::string zmq_error_text() { return zmq_strerror(zmq_errno()); }

ZmqSocket::ZmqSocket() = default;
ZmqSocket::~ZmqSocket() { close(); }

std::string ZmqSocket::open(int type, const char* type_name) {
  context_ = zmq_ctx_new();
  if (!context_) return "zmq_ctx_new: " + zmq_error_text();
  socket_ = zmq_socket(context_, type);
  if (!socket_) return std::string("zmq_socket(") + type_name + "): " + zmq_error_text();
  return {};
}

namespace {

// The socket file of an ipc:// endpoint ("" for other transports and for Linux's abstract
// namespace, ipc://@NAME).
std::string ipc_socket_path(std::string_view endpoint) {
  constexpr std::string_view kIpc = "ipc://";
  if (endpoint.rfind(kIpc, 0) != 0 || endpoint.size() == kIpc.size() || endpoint[kIpc.size()] == '@') return {};
  return std::string(endpoint.substr(kIpc.size()));
}

// Removes a socket file nobody listens on (connect is refused): the one our closed socket left.
// A file that another process has bound since (it replaces the file and listens) is kept.
void remove_stale_socket_file(const std::string& path) {
  struct stat st{};
  if (::lstat(path.c_str(), &st) != 0 || !S_ISSOCK(st.st_mode)) return;
  sockaddr_un address{};
  if (path.size() >= sizeof(address.sun_path)) return;
  address.sun_family = AF_UNIX;
  std::memcpy(address.sun_path, path.c_str(), path.size() + 1);
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return;
  const bool refused = ::connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0 &&
                       errno == ECONNREFUSED;
  ::close(fd);
  if (refused && ::unlink(path.c_str()) != 0)
    spdlog::debug("cannot remove the socket file {}: {}", path, std::strerror(errno));
}

}  // namespace

// Closes the socket and the context, then removes the socket file of the ipc:// endpoint it
// was bound to (libzmq 4.3 unlinks only the files of ipc://* wildcards; docs/reliability.md),
// unless another socket listens there by then.
void ZmqSocket::close() {
  std::string ipc_path;
  if (socket_) {
    char last[512] = {};
    size_t size = sizeof(last);
    if (zmq_getsockopt(socket_, ZMQ_LAST_ENDPOINT, last, &size) == 0) ipc_path = ipc_socket_path(last);
    zmq_close(socket_);
  }
  socket_ = nullptr;
  zap_.reset();
  if (context_) zmq_ctx_term(context_);  // the listener is closed once this returns
  context_ = nullptr;
  if (!ipc_path.empty()) remove_stale_socket_file(ipc_path);
}

std::string ZmqSocket::allow_only_keys_in(const std::string& dir) {
  std::set<std::string> keys;
  std::vector<std::string> skipped;
  if (std::string e = load_curve_allow_dir(dir, keys, skipped); !e.empty()) return e;
  // Both sockets load the list; what it holds is said once per directory (issue 20).
  static std::mutex said_mutex;
  static std::set<std::string> said;
  bool first = false;
  {
    std::lock_guard lock(said_mutex);
    first = said.insert(dir).second;
  }
  for (const auto& name : skipped) {
    if (!first) break;
    if (name.size() > 7 && name.substr(name.size() - 7) == ".secret")
      spdlog::warn("--curve-allow {}: {} is a secret key: it belongs to its client only, not here (ignored)", dir, name);
    else
      spdlog::debug("--curve-allow {}: {} ignored (not NAME.public)", dir, name);
  }
  auto zap = std::make_unique<ZapAllowList>();
  const std::size_t count = keys.size();
  if (std::string e = zap->start(context_, std::move(keys), dir); !e.empty()) return e;
  zap_ = std::move(zap);
  spdlog::debug("--curve-allow {}: {} client keys", dir, count);
  return {};
}

std::string set_curve_server(void* socket, const std::string& secret_key_file, std::string& out_public_key) {
  if (secret_key_file.empty()) return {};
  std::string secret;
  if (std::string e = read_curve_key_file(secret_key_file, secret); !e.empty()) return e;
  const int one = 1;
  if (zmq_setsockopt(socket, ZMQ_CURVE_SERVER, &one, sizeof(one)) != 0 ||
      zmq_setsockopt(socket, ZMQ_CURVE_SECRETKEY, secret.c_str(), 40) != 0)
    return "CURVE: " + zmq_error_text() + " (is libzmq built with CURVE?)";
  out_public_key = curve_public_from_secret(secret);
  return {};
}

std::string bind_socket(void* socket, const std::string& endpoint, const std::string& what, bool allow_remote, bool curve_on,
                        std::string& out_bound) {
  if (std::string e = check_bind_endpoint(endpoint, allow_remote, what); !e.empty()) return e;
  if (std::string e = prepare_ipc_endpoint(endpoint, what); !e.empty()) return e;
  // "localhost" and "[::1]" as documented (issue 11): ZeroMQ needs 127.0.0.1 and ZMQ_IPV6.
  bool ipv6 = false;
  const std::string address = zmq_bind_address(endpoint, ipv6);
  if (ipv6) {
    const int one = 1;
    zmq_setsockopt(socket, ZMQ_IPV6, &one, sizeof(one));
  }
  if (zmq_bind(socket, address.c_str()) != 0) {
    const int err = zmq_errno();
    if (err == EADDRINUSE)
      return what + " " + endpoint + ": address in use (" +
             (endpoint.rfind("ipc://", 0) == 0 ? std::string("another socket of this or another process is bound there; ")
                                               : std::string("another bodyd running? ")) +
             "stop it, or choose another " + what + " endpoint)";
    return what + " " + endpoint + ": cannot bind: " + zmq_strerror(err) +
           (err == EINVAL || err == EPROTONOSUPPORT ? " (write ipc:///PATH or tcp://127.0.0.1:PORT)" : "");
  }
  char last[512] = {};
  size_t size = sizeof(last);
  if (zmq_getsockopt(socket, ZMQ_LAST_ENDPOINT, last, &size) == 0) out_bound = last;
  else out_bound = endpoint;
  if (!is_local_endpoint(endpoint)) {
    if (!curve_on)
      spdlog::warn("{} {}: bound to a non-loopback address WITHOUT encryption: anyone on the network can {}. "
                   "Configure CURVE (bodyd --gen-keys DIR; --curve-secret-key DIR/server.secret)",
                   what, endpoint, what == "--control" ? "control bodyd" : "watch this body's motion");
    else
      spdlog::info("{} {}: reachable from other machines; CURVE encryption is on", what, endpoint);
  }
  return {};
}

std::size_t descriptors_open() {
  DIR* dir = ::opendir("/proc/self/fd");
  if (!dir) return 0;
  std::size_t n = 0;
  while (const dirent* e = ::readdir(dir))
    if (e->d_name[0] != '.') ++n;
  ::closedir(dir);
  return n > 0 ? n - 1 : 0;  // not the directory's own
}

std::size_t connection_cap(std::size_t min, std::size_t max) {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return max;
  const std::size_t open = descriptors_open();
  const std::size_t free = limit.rlim_cur > open ? static_cast<std::size_t>(limit.rlim_cur) - open : 0;
  return std::clamp(free / 4, min, max);
}

bool is_connection_of(int fd, const std::string& bound_endpoint) {
  sockaddr_storage local{};
  socklen_t len = sizeof local;
  int type = 0;
  socklen_t type_len = sizeof type;
  return ::getsockname(fd, reinterpret_cast<sockaddr*>(&local), &len) == 0 &&
         ::getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &type_len) == 0 && type == SOCK_STREAM &&
         (bound_endpoint.rfind("ipc://", 0) == 0 ? local.ss_family == AF_UNIX : local.ss_family != AF_UNIX);
}

namespace {
std::atomic<int> guards{0};  // a unique inproc endpoint per guarded socket
}

void drain_monitor(void* pair, const std::function<void(std::uint16_t, std::uint32_t)>& on_event) {
  // Events are two frames: 2 bytes event, 4 bytes value (descriptor or errno); the endpoint.
  for (int n = 0; n < 1000; ++n) {
    zmq_msg_t event, endpoint;
    zmq_msg_init(&event);
    if (zmq_msg_recv(&event, pair, ZMQ_DONTWAIT) < 0) {
      zmq_msg_close(&event);
      return;
    }
    std::uint16_t id = 0;
    std::uint32_t value = 0;
    if (zmq_msg_size(&event) >= 6) {
      std::memcpy(&id, zmq_msg_data(&event), 2);
      std::memcpy(&value, static_cast<const char*>(zmq_msg_data(&event)) + 2, 4);
    }
    const bool more = zmq_msg_more(&event);
    zmq_msg_close(&event);
    if (more) {
      zmq_msg_init(&endpoint);
      (void)zmq_msg_recv(&endpoint, pair, 0);
      zmq_msg_close(&endpoint);
    }
    on_event(id, value);
  }
}

ConnectionGuard::~ConnectionGuard() { stop(); }

std::string ConnectionGuard::start(void* context, void* socket, const std::string& what, std::size_t max_connections) {
  what_ = what;
  max_ = max_connections;
  const std::string endpoint = "inproc://bodyd-connection-guard-" + std::to_string(guards++);
  if (zmq_socket_monitor(socket, endpoint.c_str(),
                         ZMQ_EVENT_ACCEPTED | ZMQ_EVENT_ACCEPT_FAILED | ZMQ_EVENT_DISCONNECTED) != 0)
    return what + ": cannot monitor the socket: " + zmq_error_text();
  socket_ = socket;
  pair_ = zmq_socket(context, ZMQ_PAIR);
  const int unlimited = 0, zero = 0;
  if (!pair_ || zmq_setsockopt(pair_, ZMQ_RCVHWM, &unlimited, sizeof unlimited) != 0 ||
      zmq_setsockopt(pair_, ZMQ_LINGER, &zero, sizeof zero) != 0 || zmq_connect(pair_, endpoint.c_str()) != 0)
    return what + ": cannot monitor the socket: " + zmq_error_text();
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
  return {};
}

void ConnectionGuard::set_bound(const std::string& bound_endpoint) {
  std::lock_guard lock(mutex_);
  bound_ = bound_endpoint;
  ipc_path_ = ipc_socket_path(bound_endpoint);
}

void ConnectionGuard::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
  if (socket_) zmq_socket_monitor(socket_, nullptr, 0);
  socket_ = nullptr;
  if (pair_) zmq_close(pair_);
  pair_ = nullptr;
  std::lock_guard lock(mutex_);
  if (hidden_ && ::rename((ipc_path_ + ".full").c_str(), ipc_path_.c_str()) == 0) hidden_ = false;
}

void ConnectionGuard::run() {
  while (!stop_.load()) {
    zmq_pollitem_t item{pair_, 0, ZMQ_POLLIN, 0};
    if (zmq_poll(&item, 1, 100) <= 0) continue;
    drain_monitor(pair_, [this](std::uint16_t event, std::uint32_t value) { on_event(event, value); });
    gate();
  }
}

void ConnectionGuard::on_event(std::uint16_t event, std::uint32_t value) {
  const int fd = static_cast<int>(value);
  if (event == ZMQ_EVENT_ACCEPTED) {
    peers_.push_back(fd);
    if (peers_.size() >= max_ && !cap_logged_) {
      cap_logged_ = true;
      spdlog::warn("{}: {} connections, the most (a quarter of the free file descriptors, at most 64); more are "
                   "refused until one leaves (logged once)",
                   what_, max_);
    }
    if (peers_.size() > max_) refuse(fd);
  } else if (event == ZMQ_EVENT_DISCONNECTED) {
    peers_.erase(std::remove(peers_.begin(), peers_.end(), fd), peers_.end());
  } else if (event == ZMQ_EVENT_ACCEPT_FAILED && (value == EMFILE || value == ENFILE)) {
    if (!exhaustion_logged_) {
      exhaustion_logged_ = true;
      spdlog::warn("{}: out of file descriptors ({}; ulimit -n): its newest connection is closed to let the waiting "
                   "one in; raise the limit if this is not an attack (logged once)",
                   what_, std::strerror(static_cast<int>(value)));
    }
    if (!peers_.empty()) refuse(peers_.back());
  }
}

// Shuts a connection down (libzmq then closes it and reports DISCONNECTED), if it is still
// ours: a descriptor closed and reused since its event is left alone.
void ConnectionGuard::refuse(int fd) {
  std::string bound;
  {
    std::lock_guard lock(mutex_);
    bound = bound_;
  }
  if (!is_connection_of(fd, bound)) {
    peers_.erase(std::remove(peers_.begin(), peers_.end(), fd), peers_.end());
    return;
  }
  ::shutdown(fd, SHUT_RDWR);
  refused_.fetch_add(1, std::memory_order_relaxed);
}

// An ipc:// socket file is hidden while the cap is reached and back once a connection left.
void ConnectionGuard::gate() {
  std::lock_guard lock(mutex_);
  if (ipc_path_.empty()) return;
  const bool full = peers_.size() >= max_;
  if (full && !hidden_ && ::rename(ipc_path_.c_str(), (ipc_path_ + ".full").c_str()) == 0) hidden_ = true;
  if (!full && hidden_ && ::rename((ipc_path_ + ".full").c_str(), ipc_path_.c_str()) == 0) hidden_ = false;
}

}  // namespace bodyd::daemon
