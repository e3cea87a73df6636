#include "zmq_util.h"

#include "bodyd/daemon/curve_allow.h"
#include "bodyd/daemon/endpoint.h"

#include <spdlog/spdlog.h>
#include <zmq.h>

#include <cerrno>
#include <mutex>
#include <set>
#include <cstring>
#include <string_view>

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

}  // namespace bodyd::daemon
