#include "bodyd/io/zmq/endpoint.h"

#include "bodyd/base/loopback.h"
#include "bodyd/paths/private_dir.h"

#include <zmq.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

namespace bodyd::daemon {
namespace {

bool starts_with(std::string_view s, std::string_view p) { return s.substr(0, p.size()) == p; }

// The host part of "tcp://HOST:PORT" ("[::1]" keeps its brackets), or nullopt-like empty.
std::string_view tcp_host(std::string_view endpoint) {
  std::string_view rest = endpoint.substr(6);  // after "tcp://"
  if (rest.find(';') != std::string_view::npos) return {};  // "source;destination" is for connect
  const auto colon = rest.rfind(':');
  if (colon == std::string_view::npos) return {};
  return rest.substr(0, colon);
}

}  // namespace

bool is_local_endpoint(std::string_view endpoint) {
  if (starts_with(endpoint, "ipc://") || starts_with(endpoint, "inproc://")) return true;
  if (!starts_with(endpoint, "tcp://")) return false;
  // bodyd's one loopback rule (bodyd/base/loopback.h), plus ZeroMQ's name of the loopback interface.
  const std::string_view host = tcp_host(endpoint);
  return host == "lo" || is_loopback_host(host);
}

std::string check_bind_endpoint(std::string_view endpoint, bool allow_remote, std::string_view what) {
  const std::string ep(endpoint);
  const std::string opt(what);
  if (endpoint.empty()) return opt + ": empty endpoint";
  if (endpoint.find("://") == std::string_view::npos)
    return opt + " " + ep + ": not a ZeroMQ endpoint; write ipc:///path or tcp://127.0.0.1:PORT";
  if (starts_with(endpoint, "tcp://") && tcp_host(endpoint).empty())
    return opt + " " + ep + ": expected tcp://HOST:PORT (PORT may be * or 0 for any free port)";
  if (starts_with(endpoint, "ipc://") && endpoint.size() == 6) return opt + " " + ep + ": ipc:// needs a path";
  if (is_local_endpoint(endpoint)) return {};
  if (allow_remote) return {};
  return opt + " " + ep +
         ": refusing to bind where other machines can connect (body motion identifies people). "
         "Use ipc:///PATH or tcp://127.0.0.1:PORT, or pass --allow-remote (and configure CURVE keys: "
         "bodyd --gen-keys DIR, then --curve-secret-key DIR/server.secret; see docs/daemon.md)";
}

std::string zmq_bind_address(std::string_view endpoint, bool& out_ipv6) {
  out_ipv6 = false;
  if (!starts_with(endpoint, "tcp://")) return std::string(endpoint);
  const std::string_view host = tcp_host(endpoint);
  const std::string_view port = endpoint.substr(6 + host.size());  // ":PORT"
  // ZeroMQ reads a bind host as an interface name or a numeric address, so "localhost" fails
  // with "No such device"; bind the IPv4 loopback address it stands for.
  if (host == "localhost") return "tcp://127.0.0.1" + std::string(port);
  // A bracketed IPv6 address binds only on a socket with ZMQ_IPV6 set.
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') out_ipv6 = true;
  return std::string(endpoint);
}

std::string check_private_directory(const std::filesystem::path& dir) {
  const std::string problem = paths::private_directory_problem(dir);
  if (problem.empty() || problem.find(" (mode ") == std::string::npos) return problem;
  return problem + "; bodyd keeps its sockets in a private directory (mode 0700, owned by you, not a symlink). "
                   "Remove it (rm -r " + dir.string() + ") so bodyd can create it, or choose another endpoint";
}

std::string prepare_ipc_endpoint(std::string_view endpoint, std::string_view what) {
  if (!starts_with(endpoint, "ipc://")) return {};
  const std::filesystem::path path(std::string(endpoint.substr(6)));
  const std::string opt(what);
  const std::string ep(endpoint);
  if (path.string().empty() || path.string()[0] == '@') return {};  // abstract namespace: nothing on disk
  const std::filesystem::path dir = path.parent_path();
  std::error_code ec;
  bool created = false;
  if (!dir.empty()) {
    struct stat st {};
    if (::lstat(dir.c_str(), &st) != 0 && errno == ENOENT) {
      // Only this user may connect to a socket in a 0700 directory. The last component is made
      // with mkdir(0700) itself, so it is never open to others, not even for a moment.
      if (dir.has_parent_path()) std::filesystem::create_directories(dir.parent_path(), ec);
      if (ec) return opt + " " + ep + ": cannot create directory " + dir.parent_path().string() + ": " + ec.message();
      if (::mkdir(dir.c_str(), 0700) != 0 && errno != EEXIST)
        return opt + " " + ep + ": cannot create directory " + dir.string() + ": " + std::strerror(errno);
      created = true;
    }
    // The default directory (/tmp/bodyd), and any bodyd creates, must be private: a directory
    // (not a symlink someone else planted), owned by this user, with no access for others.
    const std::filesystem::path default_dir = std::filesystem::path(kDefaultIpcDirectory);
    if (created || dir.lexically_normal() == default_dir)
      if (std::string e = check_private_directory(dir); !e.empty()) return opt + " " + ep + ": " + e;
  }
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode))
      return opt + " " + ep + ": " + path.string() + " is a directory; name a socket file inside it (e.g. ipc://" +
             (path / "pose").string() + ")";
    if (!S_ISSOCK(st.st_mode))
      return opt + " " + ep + ": " + path.string() +
             " exists and is not a socket; bodyd does not replace other files (remove it, or choose another path)";
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.string().size() >= sizeof(addr.sun_path))
      return opt + " " + ep + ": path too long for a Unix socket";
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd >= 0) {
      const bool listening = ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0;
      ::close(fd);
      if (listening)
        return opt + " " + ep +
               ": in use: a process is listening on it (another bodyd running? stop it, or choose another " + opt +
               " endpoint)";
    }
  }
  return {};
}

std::string generate_curve_keys(const std::filesystem::path& dir, CurveKeyPair& out_keys, const std::string& name) {
  if (!zmq_has("curve")) return "this libzmq was built without CURVE support";
  char pub[41] = {}, sec[41] = {};
  if (zmq_curve_keypair(pub, sec) != 0) return std::string("zmq_curve_keypair: ") + zmq_strerror(zmq_errno());
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return dir.string() + ": cannot create directory: " + ec.message();
  const bool server = name == "server";
  const auto pub_path = dir / (name + ".public");
  const auto sec_path = dir / (name + ".secret");
  for (const auto& p : {pub_path, sec_path})
    if (std::filesystem::exists(p, ec)) return p.string() + ": exists; not overwriting keys (delete it first)";
  {
    // Create the secret file with mode 0600 before anything is written to it.
    const int fd = ::open(sec_path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0) return sec_path.string() + ": " + std::strerror(errno);
    const std::string text =
        (server ? std::string("# bodyd CURVE server secret key (Z85). Keep private.\n")
                : "# bodyd CURVE client secret key (Z85) of \"" + name + "\". Keep private; for the client only.\n") +
        sec + "\n";
    const bool ok = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
    ::close(fd);
    if (!ok) return sec_path.string() + ": write failed";
  }
  std::ofstream out(pub_path);
  out << (server ? std::string("# bodyd CURVE server public key (Z85). Give it to clients (ZMQ_CURVE_SERVERKEY).\n")
                 : "# bodyd CURVE client public key (Z85) of \"" + name + "\". Put it in bodyd's --curve-allow directory.\n")
      << pub << "\n";
  if (!out) return pub_path.string() + ": write failed";
  out_keys.public_key = pub;
  out_keys.secret_key = sec;
  return {};
}

}  // namespace bodyd::daemon
