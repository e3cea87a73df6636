// bodyd-viewer-bridge: subscribes to bodyd's pose stream and serves the live 3D viewer page
// (viewer/index.html, three.js from viewer/node_modules or Debian's libjs-three) with the poses pushed to the page as
// JSON over a WebSocket. Specification: docs/viewer.md.
//
// Threads: a ZeroMQ thread receives poses (bodyd::client) and formats the newest as JSON; the
// HTTP thread (poll loop over the listening socket, the connections and a wake-up pipe) serves
// files and writes each new pose to every WebSocket. A slow browser loses poses, never delays
// the others: a connection with more than kMaxQueuedBytes unsent skips poses until it drains.
#include "bodyd/viewer/websocket.h"

#include "bodyd/client/client.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <list>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#ifndef BODYD_VIEWER_DIR
#define BODYD_VIEWER_DIR "viewer"
#endif

namespace fs = std::filesystem;
using namespace bodyd;
using namespace bodyd::viewer;

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop.store(true); }

constexpr std::size_t kMaxQueuedBytes = 256 * 1024;

// What the ZeroMQ thread hands to the HTTP thread.
struct Shared {
  std::mutex mutex;
  std::string pose_json;       // newest pose message
  std::uint64_t pose_version = 0;
  std::string skeleton_json;   // newest skeleton message
  std::uint64_t skeleton_version = 0;
  std::uint64_t poses = 0, dropped = 0, malformed = 0;
};

struct Connection {
  int fd = -1;
  bool websocket = false;
  bool close_after_write = false;
  std::string in;
  std::vector<std::uint8_t> out;
  std::size_t out_at = 0;
  std::uint64_t skipped = 0;
  std::uint64_t pose_version = 0, skeleton_version = 0;  // the newest sent on this WebSocket
  [[nodiscard]] std::size_t queued() const { return out.size() - out_at; }
  void queue(std::string_view s) { out.insert(out.end(), s.begin(), s.end()); }
};

std::optional<std::string> read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string content_type(const fs::path& p) {
  const std::string ext = p.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  return "application/octet-stream";
}

// A file name the page may ask for: letters, digits, '.', '-', '_', not starting with '.'.
bool safe_name(std::string_view name) {
  if (name.empty() || name.front() == '.') return false;
  return std::all_of(name.begin(), name.end(),
                     [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_'; });
}

struct Paths {
  fs::path web_root;  // index.html, viewer.js
  fs::path three_dir;  // three.js build folder (three.module.js, three.core.js)
};

class Server {
 public:
  Server(int listen_fd, int wake_fd, const Paths& paths, Shared& shared, std::string endpoint)
      : listen_fd_(listen_fd), wake_fd_(wake_fd), paths_(paths), shared_(shared), endpoint_(std::move(endpoint)) {}

  void run() {
    std::vector<pollfd> fds;
    while (!g_stop.load()) {
      fds.clear();
      fds.push_back({listen_fd_, POLLIN, 0});
      fds.push_back({wake_fd_, POLLIN, 0});
      for (const Connection& c : conns_) {
        fds.push_back({c.fd, static_cast<short>(POLLIN | (c.queued() ? POLLOUT : 0)), 0});
      }
      const int n = ::poll(fds.data(), fds.size(), 100);
      if (n < 0) {
        if (errno == EINTR) continue;
        spdlog::error("poll: {}", std::strerror(errno));
        return;
      }
      if (fds[1].revents & POLLIN) {
        char buf[256];
        while (::read(wake_fd_, buf, sizeof buf) > 0) {
        }
      }
      publish_new();
      size_t i = 2;
      for (auto it = conns_.begin(); it != conns_.end(); ++i) {
        bool keep = true;
        if (fds[i].revents & (POLLIN | POLLHUP | POLLERR)) keep = on_readable(*it);
        if (keep && it->queued() && (fds[i].revents & POLLOUT)) keep = on_writable(*it);
        if (keep && it->close_after_write && it->queued() == 0) keep = false;
        if (!keep) {
          ::close(it->fd);
          it = conns_.erase(it);
        } else {
          ++it;
        }
      }
      if (fds[0].revents & POLLIN) accept_all();
    }
    for (Connection& c : conns_) ::close(c.fd);
  }

 private:
  void accept_all() {
    while (true) {
      const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
      if (fd < 0) return;
      if (conns_.size() >= 64) {
        ::close(fd);
        continue;
      }
      Connection c;
      c.fd = fd;
      conns_.push_back(std::move(c));
    }
  }

  // New pose/skeleton from the ZeroMQ thread to every WebSocket that has not had them.
  void publish_new() {
    std::string pose, skeleton;
    std::uint64_t pose_version = 0, skeleton_version = 0;
    {
      std::lock_guard lock(shared_.mutex);
      skeleton_version = shared_.skeleton_version;
      pose_version = shared_.pose_version;
      if (skeleton_version != skeleton_version_) skeleton = shared_.skeleton_json;
      if (pose_version != pose_version_) pose = shared_.pose_json;
    }
    skeleton_version_ = skeleton_version;
    pose_version_ = pose_version;
    for (Connection& c : conns_) {
      if (!c.websocket) continue;
      if (!skeleton.empty() && c.skeleton_version < skeleton_version) {
        send_ws(c, skeleton);
        c.skeleton_version = skeleton_version;
      }
      if (pose.empty() || c.pose_version >= pose_version) continue;
      if (c.queued() > kMaxQueuedBytes) {
        ++c.skipped;
      } else {
        send_ws(c, pose);
      }
      c.pose_version = pose_version;
    }
  }

  void send_ws(Connection& c, std::string_view text) {
    if (c.out_at > 0 && c.out_at == c.out.size()) {
      c.out.clear();
      c.out_at = 0;
    }
    append_server_frame(Opcode::kText, text, c.out);
    (void)on_writable(c);  // try at once; POLLOUT handles the rest
  }

  bool on_writable(Connection& c) {
    while (c.queued()) {
      const ssize_t n = ::send(c.fd, c.out.data() + c.out_at, c.queued(), MSG_NOSIGNAL);
      if (n < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
      c.out_at += static_cast<size_t>(n);
    }
    c.out.clear();
    c.out_at = 0;
    return true;
  }

  bool on_readable(Connection& c) {
    char buf[4096];
    while (true) {
      const ssize_t n = ::recv(c.fd, buf, sizeof buf, 0);
      if (n == 0) return false;
      if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK) break;
        if (errno == EINTR) continue;
        return false;
      }
      c.in.append(buf, static_cast<size_t>(n));
      if (c.in.size() > kMaxRequestHeadBytes + kMaxClientPayload + 16) break;
    }
    return c.websocket ? on_ws_data(c) : on_http_data(c);
  }

  bool on_ws_data(Connection& c) {
    while (true) {
      ClientFrame frame;
      size_t used = 0;
      std::string error;
      const auto r = parse_client_frame(std::span(reinterpret_cast<const std::uint8_t*>(c.in.data()), c.in.size()), frame,
                                        used, error);
      if (r == FrameParse::kNeedMore) return true;
      if (r == FrameParse::kError) {
        spdlog::debug("websocket: {}; closing", error);
        const std::uint8_t code[2] = {0x03, 0xEA};  // 1002 protocol error
        append_server_frame(Opcode::kClose, std::span(code, 2), c.out);
        c.close_after_write = true;
        c.in.clear();
        return on_writable(c);
      }
      c.in.erase(0, used);
      if (frame.opcode == Opcode::kClose) {
        append_server_frame(Opcode::kClose, std::span(frame.payload.data(), std::min<size_t>(frame.payload.size(), 2)), c.out);
        c.close_after_write = true;
        return on_writable(c);
      }
      if (frame.opcode == Opcode::kPing) append_server_frame(Opcode::kPong, frame.payload, c.out);
      // Text and binary frames from the page carry nothing the bridge uses.
    }
  }

  bool on_http_data(Connection& c) {
    const size_t end = c.in.find("\r\n\r\n");
    if (end == std::string::npos) {
      if (c.in.size() > kMaxRequestHeadBytes) {
        c.queue(http_response(431, "Request Header Fields Too Large", "text/plain", "request head too large\n"));
        c.close_after_write = true;
      }
      return true;
    }
    HttpRequest req;
    const std::string error = parse_http_request(std::string_view(c.in).substr(0, end), req);
    c.in.erase(0, end + 4);
    c.close_after_write = true;
    if (!error.empty()) {
      c.queue(http_response(400, "Bad Request", "text/plain", error + "\n"));
      return true;
    }
    if (req.method != "GET" && req.method != "HEAD") {
      c.queue(http_response(405, "Method Not Allowed", "text/plain", "only GET\n"));
      return true;
    }
    if (req.target == "/ws") {
      std::string ws_error;
      const std::string response = websocket_handshake_response(req, ws_error);
      if (response.empty()) {
        c.queue(http_response(400, "Bad Request", "text/plain", ws_error + "\n"));
        return true;
      }
      c.queue(response);
      c.websocket = true;
      c.close_after_write = false;
      // The newest skeleton and pose at once, so the page draws without waiting.
      {
        std::lock_guard lock(shared_.mutex);
        if (!shared_.skeleton_json.empty()) append_server_frame(Opcode::kText, shared_.skeleton_json, c.out);
        if (!shared_.pose_json.empty()) append_server_frame(Opcode::kText, shared_.pose_json, c.out);
        c.skeleton_version = shared_.skeleton_version;
        c.pose_version = shared_.pose_version;
      }
      int websockets = 0;
      for (const Connection& o : conns_) websockets += o.websocket ? 1 : 0;
      spdlog::info("viewer connected ({} open)", websockets);
      return on_ws_data(c);
    }
    if (req.target == "/status") {
      nlohmann::json status;
      {
        std::lock_guard lock(shared_.mutex);
        status = {{"endpoint", endpoint_},
                  {"poses", shared_.poses},
                  {"dropped", shared_.dropped},
                  {"malformed", shared_.malformed},
                  {"skeleton", !shared_.skeleton_json.empty()}};
      }
      int websockets = 0;
      for (const Connection& o : conns_) websockets += o.websocket ? 1 : 0;
      status["websockets"] = websockets;
      c.queue(http_response(200, "OK", "application/json", status.dump() + "\n"));
      return true;
    }
    std::optional<fs::path> file;
    if (req.target == "/" || req.target == "/index.html") {
      file = paths_.web_root / "index.html";
    } else if (req.target == "/viewer.js") {
      file = paths_.web_root / "viewer.js";
    } else if (req.target.rfind("/three/", 0) == 0 && safe_name(req.target.substr(7)) &&
               fs::path(req.target).extension() == ".js") {
      file = paths_.three_dir / req.target.substr(7);
    }
    std::optional<std::string> body = file ? read_file(*file) : std::nullopt;
    if (!body) {
      std::string why = fmt::format("{} not found\n", req.target);
      if (file && req.target.rfind("/three/", 0) == 0) {
        why += fmt::format("three.js is missing: run 'npm install' in viewer/ ({} does not exist)\n", file->string());
      }
      c.queue(http_response(404, "Not Found", "text/plain; charset=utf-8", why));
      return true;
    }
    std::string response = http_response(200, "OK", content_type(*file), *body);
    if (req.method == "HEAD") response.resize(response.find("\r\n\r\n") + 4);
    c.queue(response);
    return on_writable(c);
  }

  int listen_fd_, wake_fd_;
  Paths paths_;
  Shared& shared_;
  std::string endpoint_;
  std::list<Connection> conns_;
  std::uint64_t pose_version_ = 0, skeleton_version_ = 0;
};

// Receives poses until g_stop; formats the newest as JSON and wakes the HTTP thread.
void zmq_thread(client::Client& cl, Shared& shared, int wake_write_fd) {
  protocol::PoseMessage pose;
  std::uint32_t skeleton_id = 0;
  while (!g_stop.load()) {
    const client::Received r = cl.receive(pose, std::chrono::milliseconds(100));
    if (r == client::Received::kTimeout) continue;
    if (r == client::Received::kError) {
      spdlog::error("pose stream: {}", cl.error());
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      continue;
    }
    std::string skeleton_json;
    const auto& skel = cl.current_skeleton();
    if (skel && skel->skeleton_id != skeleton_id) {
      skeleton_id = skel->skeleton_id;
      nlohmann::json j = client::skeleton_to_json(*skel);
      j["type"] = "skeleton";
      skeleton_json = j.dump();
    }
    std::string pose_json;
    if (r == client::Received::kPose) {
      nlohmann::ordered_json j = client::pose_to_json(pose, skel ? &*skel : nullptr, false);
      j["type"] = "pose";
      pose_json = j.dump();
    }
    {
      std::lock_guard lock(shared.mutex);
      if (!skeleton_json.empty()) {
        shared.skeleton_json = std::move(skeleton_json);
        ++shared.skeleton_version;
      }
      if (!pose_json.empty()) {
        shared.pose_json = std::move(pose_json);
        ++shared.pose_version;
      }
      shared.poses = cl.stats().poses;
      shared.dropped = cl.stats().dropped;
      shared.malformed = cl.stats().malformed;
    }
    const char byte = 1;
    (void)!::write(wake_write_fd, &byte, 1);
  }
}

// "HOST:PORT" -> a listening IPv4 socket; the bound port in `out_port`. Empty string on success.
std::string listen_on(const std::string& spec, bool allow_remote, int& out_fd, int& out_port) {
  const size_t colon = spec.rfind(':');
  if (colon == std::string::npos) return fmt::format("--http '{}': expected HOST:PORT, e.g. 127.0.0.1:8080", spec);
  const std::string host = spec.substr(0, colon);
  int port = -1;
  try {
    size_t used = 0;
    port = std::stoi(spec.substr(colon + 1), &used);
    if (used != spec.size() - colon - 1) port = -1;
  } catch (const std::exception&) {
  }
  if (port < 0 || port > 65535) return fmt::format("--http '{}': the port must be 0..65535", spec);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::inet_pton(AF_INET, host.c_str(), &addr.sin_addr) != 1) {
    return fmt::format("--http '{}': '{}' is not an IPv4 address", spec, host);
  }
  if (!allow_remote && (ntohl(addr.sin_addr.s_addr) >> 24) != 127) {
    return fmt::format("--http '{}': not a loopback address; the viewer has no authentication, pass --allow-remote "
                       "to serve it to the network anyway",
                       spec);
  }
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return fmt::format("socket: {}", std::strerror(errno));
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(fd, 16) != 0) {
    const std::string e = std::strerror(errno);
    ::close(fd);
    return fmt::format("--http {}: cannot listen: {} (another program on that port? pick another, or port 0)", spec, e);
  }
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  out_fd = fd;
  out_port = ntohs(addr.sin_port);
  return {};
}

// three.js: the npm copy (viewer/node_modules, `npm ci --prefix viewer`) when present, else Debian's
// libjs-three.
fs::path default_three_dir() {
  const fs::path npm = fs::path(BODYD_VIEWER_DIR) / "node_modules" / "three" / "build";
  if (fs::exists(npm / "three.module.js")) return npm;
  return "/usr/share/javascript/three";
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Serves bodyd's live 3D viewer: subscribes to the pose stream and pushes poses to the page over a "
               "WebSocket (docs/viewer.md)."};
  std::string endpoint{protocol::kDefaultPoseEndpoint};
  std::string control = "none";
  std::string http = "127.0.0.1:8080";
  bool allow_remote = false;
  Paths paths{fs::path(BODYD_VIEWER_DIR), default_three_dir()};
  std::string log_level = "info";
  app.add_option("--endpoint", endpoint, "the daemon's pose stream (PUB) endpoint")->capture_default_str();
  app.add_option("--control", control, "the daemon's control endpoint, to ask for the skeleton at start; 'none' to wait for "
                                       "it on the stream (sent every second)")
      ->capture_default_str();
  app.add_option("--http", http, "HOST:PORT to serve the page on (port 0: any free port)")->capture_default_str();
  app.add_flag("--allow-remote", allow_remote, "allow a non-loopback --http address");
  app.add_option("--web-root", paths.web_root, "folder with index.html and viewer.js")->capture_default_str();
  app.add_option("--three-dir", paths.three_dir, "three.js build folder (three.module.js, three.core.js)")
      ->capture_default_str();
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error, off")->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  spdlog::set_level(spdlog::level::from_str(log_level));
  if (!fs::exists(paths.web_root / "index.html")) {
    fmt::print(stderr, "bodyd-viewer-bridge: {} does not exist (pass --web-root the viewer/ folder)\n",
               (paths.web_root / "index.html").string());
    return 2;
  }
  if (!fs::exists(paths.three_dir / "three.module.js")) {
    spdlog::warn("three.js is missing ({}); the page cannot draw until 'npm install' is run in viewer/",
                 (paths.three_dir / "three.module.js").string());
  }
  int listen_fd = -1, port = 0;
  if (std::string e = listen_on(http, allow_remote, listen_fd, port); !e.empty()) {
    fmt::print(stderr, "bodyd-viewer-bridge: {}\n", e);
    return 2;
  }
  client::ClientOptions options;
  options.pose_endpoint = endpoint;
  options.control_endpoint = control == "none" ? "" : control;
  std::string error;
  auto cl = client::Client::connect(options, error);
  if (!cl) {
    fmt::print(stderr, "bodyd-viewer-bridge: --endpoint {}: {}\n", endpoint, error);
    return 2;
  }
  if (!options.control_endpoint.empty()) {
    protocol::SkeletonMessage skel;
    if (auto s = cl->skeleton(skel); !s) spdlog::warn("skeleton from {}: {}; waiting for it on the stream", control, s.error);
  }
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_NONBLOCK | O_CLOEXEC) != 0) {
    fmt::print(stderr, "bodyd-viewer-bridge: pipe: {}\n", std::strerror(errno));
    return 1;
  }
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  signal(SIGPIPE, SIG_IGN);

  const std::string url = fmt::format("http://{}:{}/", http.substr(0, http.rfind(':')), port);
  fmt::print("bodyd-viewer-bridge: serving {} (poses from {})\n", url, endpoint);
  std::fflush(stdout);
  Shared shared;
  std::thread zmq([&] { zmq_thread(*cl, shared, pipe_fds[1]); });
  Server server(listen_fd, pipe_fds[0], paths, shared, endpoint);
  server.run();
  g_stop.store(true);
  zmq.join();
  ::close(listen_fd);
  ::close(pipe_fds[0]);
  ::close(pipe_fds[1]);
  spdlog::info("stopped ({} poses received)", shared.poses);
  return 0;
}
