// bodyd-viewer-bridge: subscribes to bodyd's pose stream, polls the daemon's control socket for
// its status, and serves the live viewer page (viewer/index.html, three.js from viewer/node_modules
// or Debian's libjs-three). Poses, the skeleton and the daemon's status are pushed to the page as
// JSON over a WebSocket; the page's calibrate and reset buttons are forwarded to the control
// socket. HTTP and WebSocket are CivetWeb's (libcivetweb). Specification: docs/viewer.md.
//
// Threads: the pose thread receives poses (bodyd::client) and keeps the newest as JSON and the
// rate the daemon publishes at (publish_rate.h); the status thread asks the daemon for `status`
// once a second; the push thread sends what is new to every open WebSocket at most every 10 ms; CivetWeb's worker threads serve files and forward the
// buttons. A browser that falls behind loses poses (only the newest is ever sent), never delays
// the others' by more than CivetWeb's write timeout.
//
// Who may use it (issue 20 items 1, 4): every request must name localhost or an IP address in
// Host, so a DNS-rebinding page (which reaches us under its own name) cannot use it; a request carrying an Origin other
// than the bridge's own is refused, so another site's page can neither press the buttons nor read
// the pose stream over a WebSocket; POSTs take only application/json (a cross-site form or a
// no-cors fetch cannot send it); no CORS headers. Workers are never all held: WebSockets are capped
// below the worker count, each client address has its own cap, headers and bodies have deadlines.
#include "bodyd/base/loopback.h"
#include "bodyd/client/client.h"
#include "bodyd/paths/data_files.h"
#include "publish_rate.h"

#include <CLI/CLI.hpp>
#include <civetweb.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using namespace bodyd;
using namespace std::chrono_literals;

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop.store(true); }

// Requests from the page larger than this are refused (the buttons send a few bytes).
constexpr long long kMaxRequestBody = 4096;
// CivetWeb serves each connection, a WebSocket included, on a worker thread of its own until it
// closes. WebSockets are capped well below the worker count, and so is each client address, so
// pages, files and buttons always find a free worker (docs/viewer.md, docs/reliability.md).
constexpr int kWorkerThreads = 64;
constexpr std::size_t kMaxWebSockets = 16;
constexpr int kMaxConnectionsPerClient = 24;
// Accepted connections waiting for a worker (CivetWeb's connection_queue); beyond it the kernel's
// listen backlog holds them, using no descriptor of ours.
constexpr int kConnectionQueue = 16;
// Whole request headers, and a button's body, must arrive within this.
constexpr int kRequestTimeoutMs = 2000;
// ?hold-load's held requests (test-only, --enable-hold-load) at once; more are answered at once.
constexpr int kMaxHeldRequests = 4;
// Descriptors the bridge needs at most: a connection and a file per worker, the queue, and
// ZeroMQ's (two contexts, their sockets and reconnects) with room to spare.
constexpr rlim_t kDescriptorsNeeded = 2 * kWorkerThreads + kConnectionQueue + 48;

// Who may talk to the bridge. Host must be "localhost" or an IP address, with our port or none:
// a DNS-rebinding page reaches us under its own name, which is refused. An Origin, when sent,
// must be the bridge's own, http:// and the request's Host: a browser sends Origin on every
// WebSocket handshake and POST, and on cross-origin requests; curl and scripts send none (they
// are local programs that could use the control socket directly).
struct AccessPolicy {
  int port = 0;

  [[nodiscard]] bool host_ok(std::string_view host) const {
    std::string name(host), port_text;
    if (!host.empty() && host.front() == '[') {  // [v6] or [v6]:port
      const size_t close = host.find(']');
      if (close == std::string_view::npos) return false;
      name = std::string(host.substr(1, close - 1));
      if (close + 1 < host.size()) {
        if (host[close + 1] != ':') return false;
        port_text = host.substr(close + 2);
        if (port_text.empty()) return false;
      }
      in6_addr a6{};
      if (::inet_pton(AF_INET6, name.c_str(), &a6) != 1) return false;
    } else {
      if (const size_t colon = host.rfind(':'); colon != std::string_view::npos) {
        name = std::string(host.substr(0, colon));
        port_text = host.substr(colon + 1);
        if (port_text.empty()) return false;
      }
      in_addr a4{};
      const bool localhost = name.size() == 9 && mg_strncasecmp(name.c_str(), "localhost", 9) == 0;
      if (!localhost && ::inet_pton(AF_INET, name.c_str(), &a4) != 1) return false;
    }
    return port_text.empty() || port_text == std::to_string(port);
  }
  // Same origin: exactly "http://" + the (checked) Host, letter case aside.
  [[nodiscard]] static bool origin_ok(std::string_view origin, std::string_view host) {
    const std::string own = "http://" + std::string(host);
    return origin.size() == own.size() && mg_strncasecmp(origin.data(), own.c_str(), own.size()) == 0;
  }
};

// The media type of a Content-Type value, without parameters, is application/json.
bool is_json_content_type(const char* value) {
  if (!value) return false;
  std::string_view v = value;
  v = v.substr(0, v.find(';'));
  while (!v.empty() && (v.back() == ' ' || v.back() == '\t')) v.remove_suffix(1);
  while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.remove_prefix(1);
  constexpr std::string_view json = "application/json";
  return v.size() == json.size() &&
         std::equal(v.begin(), v.end(), json.begin(), [](char a, char b) { return std::tolower(a) == b; });
}

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
  fs::path web_root;   // index.html, viewer.js
  fs::path three_dir;  // three.js build folder (three.module.js, three.core.js)
};

// What the threads share. Versions tell the push thread what is new.
struct Shared {
  std::mutex mutex;
  std::string pose_json, skeleton_json, status_json;
  std::uint64_t pose_version = 0, skeleton_version = 0, status_version = 0;
  std::uint64_t poses = 0, dropped = 0, malformed = 0;
  // Poses the daemon publishes per second, from the stream's seq and publish_t_ns (PublishRate);
  // nullopt before two poses and after a second without one.
  std::optional<double> published_per_s;
  std::condition_variable changed;
};

// The bridge's view of the daemon: the last status reply and what the page shows from it.
struct DaemonView {
  std::string control_endpoint;  // empty: none configured
  bool answered = false;         // the last status request got a reply
  std::string error;             // why not
  nlohmann::json status;         // the last reply
  double frames_per_s = 0;       // poses sent by the daemon per second, from frames_out
};

// One WebSocket connection and what it has been sent.
struct WsClient {
  mg_connection* conn = nullptr;
  std::uint64_t pose_version = 0, skeleton_version = 0, status_version = 0;
};

class Bridge {
 public:
  Bridge(Paths paths, std::string endpoint, client::Client& poses, client::Client* control, std::string control_endpoint,
         bool hold_load)
      : paths_(std::move(paths)), endpoint_(std::move(endpoint)), poses_(poses), control_(control), hold_load_(hold_load) {
    daemon_.control_endpoint = std::move(control_endpoint);
  }

  Shared& shared() { return shared_; }
  // Set once the server listens (the port is known then), before any request is served.
  void set_access_policy(AccessPolicy policy) {
    policy_ = policy;
    policy_ready_.store(true, std::memory_order_release);
  }

  // ---- CivetWeb callbacks (worker threads) ----------------------------------------------

  // Every request, the WebSocket handshake included, before it is routed: who may ask
  // (AccessPolicy), and a client over its connection cap. Non-zero: answered here.
  int on_begin_request(mg_connection* conn) {
    const mg_request_info* ri = mg_get_request_info(conn);
    if (!policy_ready_.load(std::memory_order_acquire)) return reply(conn, 503, "text/plain", "starting\n");
    const char* host = mg_get_header(conn, "Host");
    if (!host) return reply(conn, 400, "text/plain", "a Host header is required\n");
    if (!policy_.host_ok(host)) {
      // A page on another name that resolves here (DNS rebinding), or a mistyped address.
      return reply(conn, 403, "text/plain",
                   fmt::format("Host '{}' is not this bridge's; open http://127.0.0.1:{}/\n", sanitize(host), policy_.port));
    }
    if (const char* origin = mg_get_header(conn, "Origin"); origin && !AccessPolicy::origin_ok(origin, host)) {
      return reply(conn, 403, "text/plain",
                   fmt::format("requests from pages of another origin ('{}') are refused\n", sanitize(origin)));
    }
    if (count_connection(conn, ri->remote_addr) > kMaxConnectionsPerClient) {
      return reply(conn, 503, "text/plain",
                   fmt::format("more than {} connections from {} at once\n", kMaxConnectionsPerClient, ri->remote_addr));
    }
    const std::string_view method = ri->request_method ? ri->request_method : "";
    if (method == "POST" && !is_json_content_type(mg_get_header(conn, "Content-Type"))) {
      return reply(conn, 415, "text/plain", "POST bodies must be JSON, with Content-Type: application/json\n");
    }
    const char* upgrade = mg_get_header(conn, "Upgrade");
    if (upgrade && mg_strcasecmp(upgrade, "websocket") == 0) {
      std::lock_guard lock(ws_slots_mutex_);
      if (ws_slots_.size() >= kMaxWebSockets) {
        return reply(conn, 503, "text/plain", fmt::format("already {} viewers connected (the most)\n", kMaxWebSockets));
      }
    }
    return 0;
  }

  // Per client address, the connections that have sent a request and are still open (one
  // request per connection: keep-alive is off). The address rides along as the connection's
  // user data until CivetWeb closes it (the request info is gone by then for some connections).
  void on_connection_close(const mg_connection* conn) {
    {
      // A WebSocket's slot is free once its connection is gone, however its handshake ended.
      std::lock_guard lock(ws_slots_mutex_);
      std::erase(ws_slots_, conn);
    }
    auto* address = static_cast<std::string*>(mg_get_user_connection_data(conn));
    if (!address) return;
    {
      std::lock_guard lock(connections_mutex_);
      auto it = connections_.find(*address);
      if (it != connections_.end() && --it->second <= 0) connections_.erase(it);
    }
    delete address;
  }

  int on_request(mg_connection* conn) {
    const mg_request_info* ri = mg_get_request_info(conn);
    const std::string method = ri->request_method ? ri->request_method : "";
    const std::string uri = ri->local_uri ? ri->local_uri : "";
    if (uri == "/api/calibrate" || uri == "/api/reset") return on_button(conn, method, uri);
    if (hold_load_ && uri == "/api/page-ready" && method == "POST") {
      {
        std::lock_guard lock(hold_mutex_);
        ++pages_ready_;
      }
      hold_changed_.notify_all();
      return reply(conn, 200, "text/plain", "ok\n");
    }
    if (hold_load_ && uri == "/hold" && method == "GET") {
      // ?hold-load (--enable-hold-load, tests only): the page's hidden image; answered once a page
      // has shown its first pose and status (POST /api/page-ready), at most 10 s later, so the load
      // event waits for both. At most kMaxHeldRequests are held at once.
      std::unique_lock lock(hold_mutex_);
      if (held_ >= kMaxHeldRequests) {
        lock.unlock();
        return reply(conn, 204, "text/plain", "");
      }
      ++held_;
      const std::uint64_t seen = pages_ready_;
      hold_changed_.wait_for(lock, 10s, [&] { return pages_ready_ > seen || g_stop.load(); });
      --held_;
      lock.unlock();
      return reply(conn, 204, "text/plain", "");
    }
    if (method != "GET" && method != "HEAD") return reply(conn, 405, "text/plain", "only GET (and POST to /api/...)\n");
    if (uri == "/ws") return reply(conn, 400, "text/plain", "/ws is a WebSocket endpoint (Upgrade: websocket)\n");
    if (uri == "/status") return reply(conn, 200, "application/json", status_json().dump() + "\n");
    std::optional<fs::path> file;
    const bool page = uri == "/" || uri == "/index.html";
    if (page) {
      file = paths_.web_root / "index.html";
    } else if (uri == "/viewer.js") {
      file = paths_.web_root / "viewer.js";
    } else if (uri.rfind("/three/", 0) == 0 && safe_name(uri.substr(7)) && fs::path(uri).extension() == ".js") {
      file = paths_.three_dir / uri.substr(7);
    }
    std::optional<std::string> body = file ? read_file(*file) : std::nullopt;
    if (!body) {
      std::string why = fmt::format("{} not found\n", uri);
      if (file && uri.rfind("/three/", 0) == 0) {
        why += fmt::format("three.js is missing ({} does not exist): apt-get install libjs-three\n", file->string());
      }
      return reply(conn, 404, "text/plain; charset=utf-8", why);
    }
    if (page) body = with_initial_state(std::move(*body), initial_state_json());
    return reply(conn, 200, content_type(*file), *body, method == "HEAD");
  }

  int on_ws_connect(const mg_connection* conn) {
    // on_begin_request refuses the handshake with a 503 when full; two at once can both pass it,
    // so the slot is taken here, where the check and the taking are one step. It is taken before
    // the handshake is answered (clients_ has the connection only after, in on_ws_ready), so a
    // client that has its 101 holds its slot.
    std::lock_guard lock(ws_slots_mutex_);
    if (ws_slots_.size() >= kMaxWebSockets) return 1;  // non-zero refuses
    ws_slots_.push_back(conn);
    return 0;
  }

  void on_ws_ready(mg_connection* conn) {
    {
      std::lock_guard lock(clients_mutex_);
      clients_.push_back({conn});
      spdlog::info("viewer connected ({} open)", clients_.size());
    }
    shared_.changed.notify_all();  // the push thread sends the newest skeleton, pose and status at once
  }

  void on_ws_close(const mg_connection* conn) {
    std::lock_guard lock(clients_mutex_);
    std::erase_if(clients_, [&](const WsClient& c) { return c.conn == conn; });
  }

  // ---- bridge threads -------------------------------------------------------------------

  // Receives poses until g_stop; keeps the newest as JSON, and the daemon's publishing rate.
  void pose_thread() {
    protocol::PoseMessage pose;
    std::uint32_t skeleton_id = 0;
    viewer::PublishRate rate;
    auto last_pose = std::chrono::steady_clock::now();
    while (!g_stop.load()) {
      const client::Received r = poses_.receive(pose, 100ms);
      if (r == client::Received::kTimeout) {
        // Only the bridge's clock can tell that the stream has stopped: a second without a pose
        // (bodyd publishes at least a few per second while it has trackers) and the rate is unknown.
        if (std::chrono::steady_clock::now() - last_pose > 1s) {
          rate.clear();
          std::lock_guard lock(shared_.mutex);
          shared_.published_per_s.reset();
        }
        continue;
      }
      if (r == client::Received::kError) {
        spdlog::error("pose stream: {}", poses_.error());
        std::this_thread::sleep_for(100ms);
        continue;
      }
      std::string skeleton_json;
      const auto& skel = poses_.current_skeleton();
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
        rate.add(pose.seq, pose.publish_t_ns);
        last_pose = std::chrono::steady_clock::now();
      }
      {
        std::lock_guard lock(shared_.mutex);
        if (!skeleton_json.empty()) {
          shared_.skeleton_json = std::move(skeleton_json);
          ++shared_.skeleton_version;
        }
        if (!pose_json.empty()) {
          shared_.pose_json = std::move(pose_json);
          ++shared_.pose_version;
        }
        shared_.poses = poses_.stats().poses;
        shared_.dropped = poses_.stats().dropped;
        shared_.malformed = poses_.stats().malformed;
        shared_.published_per_s = rate.per_s();
      }
      shared_.changed.notify_all();
    }
  }

  // Asks the daemon for its status once a second.
  void status_thread() {
    std::optional<std::pair<std::chrono::steady_clock::time_point, double>> last_frames;
    while (!g_stop.load()) {
      const auto start = std::chrono::steady_clock::now();
      if (control_) {
        client::ControlReply r;
        {
          std::lock_guard lock(control_mutex_);
          r = control_->request(nlohmann::json{{"cmd", "status"}}, 800ms);
        }
        std::lock_guard lock(daemon_mutex_);
        daemon_.answered = r.ok;
        daemon_.error = r.ok ? "" : r.error;
        if (r.ok) {
          daemon_.status = r.json;
          const double frames = r.json.value("frames_out", 0.0);
          if (last_frames && start > last_frames->first) {
            const double dt = std::chrono::duration<double>(start - last_frames->first).count();
            daemon_.frames_per_s = std::max(0.0, (frames - last_frames->second) / dt);
          }
          last_frames = std::make_pair(start, frames);
        } else {
          last_frames.reset();
          daemon_.frames_per_s = 0;
        }
      }
      {
        nlohmann::json j = status_json();
        j["type"] = "status";
        std::lock_guard lock(shared_.mutex);
        shared_.status_json = j.dump();
        ++shared_.status_version;
      }
      shared_.changed.notify_all();
      while (!g_stop.load() && std::chrono::steady_clock::now() - start < 1s) std::this_thread::sleep_for(50ms);
    }
  }

  // Sends what is new to every WebSocket, at most every 10 ms.
  void push_thread() {
    while (!g_stop.load()) {
      std::string pose, skeleton, status;
      std::uint64_t pose_version = 0, skeleton_version = 0, status_version = 0;
      {
        std::unique_lock lock(shared_.mutex);
        shared_.changed.wait_for(lock, 100ms);
        pose = shared_.pose_json;
        skeleton = shared_.skeleton_json;
        status = shared_.status_json;
        pose_version = shared_.pose_version;
        skeleton_version = shared_.skeleton_version;
        status_version = shared_.status_version;
      }
      std::lock_guard lock(clients_mutex_);
      for (WsClient& c : clients_) {
        // The skeleton before any pose that follows it.
        if (!skeleton.empty() && c.skeleton_version < skeleton_version) {
          send(c.conn, skeleton);
          c.skeleton_version = skeleton_version;
        }
        if (!pose.empty() && c.pose_version < pose_version) {
          send(c.conn, pose);
          c.pose_version = pose_version;
        }
        if (!status.empty() && c.status_version < status_version) {
          send(c.conn, status);
          c.status_version = status_version;
        }
      }
      std::this_thread::sleep_for(10ms);
    }
  }

  std::uint64_t poses_received() {
    std::lock_guard lock(shared_.mutex);
    return shared_.poses;
  }

  // At shutdown: a close frame (1001, going away; RFC 6455 section 7.4.1) to every page, whose
  // answering close ends its worker's read at once instead of at CivetWeb's next 2 s poll step.
  void close_websockets() {
    static const char going_away[2] = {'\x03', '\xe9'};
    std::lock_guard lock(clients_mutex_);
    for (WsClient& c : clients_) (void)mg_websocket_write(c.conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, going_away, 2);
  }

 private:
  static void send(mg_connection* conn, const std::string& text) {
    // A failed write closes the connection on CivetWeb's side; the close handler removes it.
    (void)mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_TEXT, text.data(), text.size());
  }

  // A header value for an error message: printable ASCII only, at most 100 characters.
  static std::string sanitize(std::string_view text) {
    std::string out;
    for (char c : text.substr(0, 100)) out += (c >= 0x20 && c < 0x7f) ? c : '?';
    return out;
  }

  // What the page draws before its WebSocket has delivered anything (issue 43 item 16: a
  // screenshot at the load event, or a page on a busy machine, showed only "connected, waiting
  // for poses"): the newest skeleton, pose and status, the messages a new WebSocket gets first,
  // as one JSON object {"skeleton", "pose", "status"} (null for what the bridge does not have yet).
  std::string initial_state_json() {
    std::lock_guard lock(shared_.mutex);
    const auto or_null = [](const std::string& message) { return message.empty() ? std::string("null") : message; };
    return "{\"skeleton\":" + or_null(shared_.skeleton_json) + ",\"pose\":" + or_null(shared_.pose_json) +
           ",\"status\":" + or_null(shared_.status_json) + "}";
  }

  // The page with `state` in its <script type="application/json" id="initial-state"> element
  // (viewer/index.html); a page without the element is served as it is. Every '<' of the JSON
  // becomes \u003c (it can only be inside a string there), so no text in it, a source's name
  // included, can end the script element ("</script>") or start a comment.
  static std::string with_initial_state(std::string page, const std::string& state) {
    static constexpr std::string_view kElement = "<script type=\"application/json\" id=\"initial-state\">{}</script>";
    const size_t at = page.find(kElement);
    if (at == std::string::npos) return page;
    std::string escaped;
    escaped.reserve(state.size());
    for (char c : state) {
      if (c == '<') escaped += "\\u003c";
      else escaped += c;
    }
    const size_t braces = at + kElement.find("{}");
    page.replace(braces, 2, escaped);
    return page;
  }

  // Counts this connection for its address (once); the count now.
  int count_connection(mg_connection* conn, const char* address) {
    std::lock_guard lock(connections_mutex_);
    if (!mg_get_user_connection_data(conn)) {
      mg_set_user_connection_data(conn, new std::string(address));
      return ++connections_[address];
    }
    return connections_[address];
  }

  // Written out by hand: CivetWeb's mg_response_header_* send nothing on a WebSocket handshake
  // request, which on_begin_request may have to refuse.
  static int reply(mg_connection* conn, int code, std::string_view type, std::string_view body, bool head_only = false) {
    const std::string head = fmt::format(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        code, mg_get_response_code_text(conn, code), type, body.size());
    mg_write(conn, head.data(), head.size());
    if (!head_only) mg_write(conn, body.data(), body.size());
    return code;
  }

  // The bridge's own counters and the daemon's status, as GET /status and the page's "status"
  // message carry them (docs/viewer.md).
  nlohmann::json status_json() {
    nlohmann::json j;
    {
      std::lock_guard lock(shared_.mutex);
      j = {{"endpoint", endpoint_},
           {"poses", shared_.poses},
           {"dropped", shared_.dropped},
           {"malformed", shared_.malformed},
           {"skeleton", !shared_.skeleton_json.empty()}};
      j["published_per_s"] = shared_.published_per_s ? nlohmann::json(*shared_.published_per_s) : nlohmann::json();
    }
    {
      std::lock_guard lock(clients_mutex_);
      j["websockets"] = clients_.size();
    }
    std::lock_guard lock(daemon_mutex_);
    nlohmann::json d = {{"control", daemon_.control_endpoint.empty() ? "none" : daemon_.control_endpoint},
                        {"answered", daemon_.answered}};
    if (!daemon_.error.empty()) d["error"] = daemon_.error;
    if (daemon_.answered) {
      d["status"] = daemon_.status;
      d["frames_per_s"] = daemon_.frames_per_s;
    }
    j["daemon"] = std::move(d);
    return j;
  }

  // POST /api/calibrate (body: {"from": "head"}, {"head_height_m": H} or {"user_height_m": H}) and
  // POST /api/reset: forwarded to the control socket; the daemon's reply is the answer.
  int on_button(mg_connection* conn, const std::string& method, const std::string& uri) {
    if (method != "POST") return reply(conn, 405, "text/plain", uri + " takes POST\n");
    if (!control_) {
      return reply(conn, 503, "application/json",
                   nlohmann::json{{"ok", false}, {"error", "the bridge has no --control endpoint"}}.dump() + "\n");
    }
    const mg_request_info* ri = mg_get_request_info(conn);
    if (ri->content_length > kMaxRequestBody) return reply(conn, 413, "text/plain", "request body too large\n");
    std::string body;
    char buf[1024];
    int n = 0;
    // The whole body within kRequestTimeoutMs (each mg_read alone may wait that long per byte).
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(kRequestTimeoutMs);
    while (body.size() <= kMaxRequestBody && std::chrono::steady_clock::now() < deadline &&
           (n = mg_read(conn, buf, sizeof buf)) > 0)
      body.append(buf, n);
    if (body.size() > kMaxRequestBody) return reply(conn, 413, "text/plain", "request body too large\n");
    if (ri->content_length > 0 && static_cast<long long>(body.size()) < ri->content_length)
      return reply(conn, 408, "text/plain", "the request body did not arrive in time\n");
    nlohmann::json request;
    if (uri == "/api/reset") {
      request = {{"cmd", "reset"}};
    } else {
      const nlohmann::json args = nlohmann::json::parse(body.empty() ? "{}" : body, nullptr, false);
      if (!args.is_object()) return reply(conn, 400, "text/plain", "the body must be a JSON object\n");
      request = {{"cmd", "calibrate"}};
      // Only the keys the page sends; anything else is the daemon's to refuse.
      for (const char* key : {"from", "head_height_m", "user_height_m"}) {
        if (args.contains(key)) request[key] = args[key];
      }
      if (request.size() == 1) request["from"] = "head";
    }
    client::ControlReply r;
    {
      std::lock_guard lock(control_mutex_);
      r = control_->request(request, 2000ms);
    }
    nlohmann::json answer = r.json.is_object() ? r.json : nlohmann::json::object();
    answer["ok"] = r.ok;
    if (!r.ok && !answer.contains("error")) answer["error"] = r.error;
    return reply(conn, r.ok ? 200 : 502, "application/json", answer.dump() + "\n");
  }

  Paths paths_;
  std::string endpoint_;
  client::Client& poses_;
  client::Client* control_;
  std::mutex control_mutex_;  // one control request at a time (REQ socket)
  Shared shared_;
  std::mutex clients_mutex_;
  std::vector<WsClient> clients_;
  // The WebSockets accepted (on_ws_connect) and not yet closed (on_connection_close): the cap
  // counts these. A mutex of its own, never held while calling CivetWeb: on_connection_close
  // runs with the connection's lock held.
  std::mutex ws_slots_mutex_;
  std::vector<const mg_connection*> ws_slots_;
  std::mutex daemon_mutex_;
  DaemonView daemon_;
  bool hold_load_ = false;
  std::mutex hold_mutex_;
  std::condition_variable hold_changed_;
  std::uint64_t pages_ready_ = 0;
  int held_ = 0;
  AccessPolicy policy_;
  std::atomic<bool> policy_ready_{false};
  std::mutex connections_mutex_;
  std::map<std::string, int, std::less<>> connections_;
};

extern "C" int request_handler(mg_connection* conn, void* self) { return static_cast<Bridge*>(self)->on_request(conn); }
extern "C" int begin_request(mg_connection* conn) {
  return static_cast<Bridge*>(mg_get_user_data(mg_get_context(conn)))->on_begin_request(conn);
}
extern "C" void connection_close(const mg_connection* conn) {
  static_cast<Bridge*>(mg_get_user_data(mg_get_context(conn)))->on_connection_close(conn);
}
extern "C" int ws_connect(const mg_connection* conn, void* self) { return static_cast<Bridge*>(self)->on_ws_connect(conn); }
extern "C" void ws_ready(mg_connection* conn, void* self) { static_cast<Bridge*>(self)->on_ws_ready(conn); }
// The page sends nothing the bridge uses; a close frame is answered with a close frame (RFC 6455
// section 5.5.1) carrying the same status code, and ends the connection. CivetWeb answers pings
// with pongs itself (enable_websocket_ping_pong, below).
extern "C" int ws_data(mg_connection* conn, int bits, char* data, size_t len, void*) {
  if ((bits & 0x0F) != MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 1;
  (void)mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, data, std::min<size_t>(len, 2));
  return 0;
}
extern "C" void ws_close(const mg_connection* conn, void* self) { static_cast<Bridge*>(self)->on_ws_close(conn); }
extern "C" int log_message(const mg_connection*, const char* message) {
  spdlog::debug("civetweb: {}", message);
  return 1;
}

// "HOST:PORT" checked: an IPv4 address (loopback unless allow_remote) and a port 0..65535.
std::string check_http_spec(const std::string& spec, bool allow_remote) {
  const size_t colon = spec.rfind(':');
  if (colon == std::string::npos) return fmt::format("--http '{}': expected HOST:PORT, e.g. 127.0.0.1:8080", spec);
  const std::string host = spec.substr(0, colon), port_text = spec.substr(colon + 1);
  if (port_text.empty() || port_text.size() > 5 || !std::all_of(port_text.begin(), port_text.end(), ::isdigit) ||
      std::stoi(port_text) > 65535) {
    return fmt::format("--http '{}': the port must be 0..65535", spec);
  }
  in_addr addr{};
  if (::inet_pton(AF_INET, host.c_str(), &addr) != 1) return fmt::format("--http '{}': '{}' is not an IPv4 address", spec, host);
  if (!allow_remote && !bodyd::is_loopback(addr)) {
    return fmt::format("--http '{}': not a loopback address; the viewer has no authentication, pass --allow-remote "
                       "to serve it to the network anyway",
                       spec);
  }
  return {};
}

// three.js: the npm copy (viewer/node_modules, `npm ci --prefix viewer`) when present, else Debian's
// libjs-three.
fs::path default_three_dir(const fs::path& web_root) {
  const fs::path npm = web_root / "node_modules" / "three" / "build";
  if (fs::exists(npm / "three.module.js")) return npm;
  return "/usr/share/javascript/three";
}

// The page, where bodyd's data files are (docs/install.md): PREFIX/share/bodyd/viewer next to an
// installed bridge, $XDG_DATA_HOME/bodyd/viewer, or viewer/ of the source tree of the build.
fs::path default_web_root() { return paths::find_data_file("viewer/index.html").path.parent_path(); }

// Out of descriptors, CivetWeb's accept thread retries accept() at once, forever (a busy loop,
// issue 20 item 6), so the bridge makes sure it cannot run out: the soft limit is raised to what
// it needs when the hard limit allows, else it refuses to start. Empty or the error.
std::string ensure_descriptors(rlim_t needed) {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0) return {};
  if (limit.rlim_cur != RLIM_INFINITY && limit.rlim_cur < needed) {
    if (limit.rlim_max != RLIM_INFINITY && limit.rlim_max < needed) {
      return fmt::format("the open-file limit is {} (ulimit -n) but the bridge needs {} descriptors ({} workers); "
                         "raise it (ulimit -n 1024)",
                         limit.rlim_max, needed, kWorkerThreads);
    }
    limit.rlim_cur = needed;
    if (::setrlimit(RLIMIT_NOFILE, &limit) != 0) return fmt::format("cannot raise the open-file limit to {}", needed);
  }
  return {};
}

// The endpoints named in the user's config file, $XDG_CONFIG_HOME/bodyd/config.json (what
// `bodyd --user-config` and the systemd unit read): "pub" (the pose stream) and "control", as
// bodyd-ctl takes "control" from it (tools/bodyd_ctl.cpp). A key the file does not set stays
// empty; a file that is missing sets none. A file that does not parse, or a key that is not a
// string, is warned about and ignored: bodyd refuses such a file itself, and says why. A bind on
// every interface (tcp://*:PORT) is connected to on 127.0.0.1.
struct ConfigEndpoints {
  fs::path file;
  std::optional<std::string> pub, control;
};

ConfigEndpoints read_config_endpoints(const fs::path& file) {
  ConfigEndpoints out{file, {}, {}};
  std::error_code ec;
  if (file.empty() || !fs::exists(file, ec)) return out;
  const std::optional<std::string> text = read_file(file);
  const nlohmann::json j = nlohmann::json::parse(text.value_or(""), nullptr, /*allow_exceptions=*/false,
                                                 /*ignore_comments=*/true);
  if (j.is_discarded() || !j.is_object()) {
    spdlog::warn("{}: not a JSON object; its endpoints are not used (bodyd --user-config says what is wrong)", file.string());
    return out;
  }
  for (const auto& [key, value] : {std::pair{"pub", &out.pub}, std::pair{"control", &out.control}}) {
    if (!j.contains(key)) continue;
    if (j[key].is_string() && !j[key].get<std::string>().empty()) {
      *value = j[key].get<std::string>();
      // bodyd binds there; "*" (every interface, with allow_remote) is not an address to connect to.
      if ((*value)->rfind("tcp://*:", 0) == 0) (*value)->replace(0, 7, "tcp://127.0.0.1");
    } else {
      spdlog::warn("{}: \"{}\" is not an endpoint string; using the default", file.string(), key);
    }
  }
  return out;
}

// mg_stop, promptly: CivetWeb's accept thread polls its listening socket in 2 s steps and sees
// the stop flag only when that poll returns, so connections of our own wake it.
void stop_server(mg_context* ctx, const std::string& host, int port) {
  std::atomic<bool> stopped{false};
  std::thread stopper([&] {
    mg_stop(ctx);
    stopped.store(true);
  });
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::inet_pton(AF_INET, host.c_str(), &addr.sin_addr) != 1) addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  for (int i = 0; i < 100 && !stopped.load(); ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd >= 0) {
      (void)::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr);
      ::close(fd);
    }
    std::this_thread::sleep_for(20ms);
  }
  stopper.join();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Serves bodyd's live viewer: subscribes to the pose stream, shows the daemon's status from its control "
               "socket, and pushes both to the page over a WebSocket (docs/viewer.md)."};
  std::string endpoint{protocol::kDefaultPoseEndpoint};
  std::string control{protocol::kDefaultControlEndpoint};
  std::string http = "127.0.0.1:8080";
  bool allow_remote = false;
  Paths paths{default_web_root(), {}};
  std::string log_level = "info";
  bool hold_load = false;
  const ConfigEndpoints config = read_config_endpoints(paths::user_config_file());
  app.add_option("--endpoint", endpoint,
                 "the daemon's pose stream (PUB) endpoint (default: \"pub\" in " + config.file.string() +
                     " when it sets one, else " + endpoint + ")");
  app.add_option("--control", control,
                 "the daemon's control endpoint: its status for the page, the skeleton at start, the calibrate and "
                 "reset buttons; 'none' for poses only (default: \"control\" in " +
                     config.file.string() + " when it sets one, else " + control + ")");
  app.add_option("--http", http, "HOST:PORT to serve the page on (port 0: any free port)")->capture_default_str();
  app.add_flag("--allow-remote", allow_remote, "allow a non-loopback --http address");
  app.add_option("--web-root", paths.web_root, "folder with index.html and viewer.js")->capture_default_str();
  app.add_option("--three-dir", paths.three_dir, "three.js build folder (three.module.js, three.core.js)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error, off")->capture_default_str();
  app.add_flag("--enable-hold-load", hold_load,
               "serve /hold and /api/page-ready for the page's ?hold-load (tests and screenshots only, docs/viewer.md)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  spdlog::set_level(spdlog::level::from_str(log_level));
  // The user's config names the daemon's endpoints unless a flag does (issue 43 item 16).
  std::string endpoint_from = "--endpoint", control_from = "--control";
  if (app.count("--endpoint") == 0) {
    endpoint_from = config.pub ? "\"pub\" in " + config.file.string() : "the default";
    endpoint = config.pub.value_or(endpoint);
  }
  if (app.count("--control") == 0) {
    control_from = config.control ? "\"control\" in " + config.file.string() : "the default";
    control = config.control.value_or(control);
  }
  if (config.pub || config.control) spdlog::info("pose stream {} ({}), control {} ({})", endpoint, endpoint_from, control, control_from);
  if (paths.three_dir.empty()) paths.three_dir = default_three_dir(paths.web_root);
  if (!fs::exists(paths.web_root / "index.html")) {
    fmt::print(stderr, "bodyd-viewer-bridge: {} does not exist (pass --web-root the viewer/ folder)\n",
               (paths.web_root / "index.html").string());
    return 2;
  }
  if (!fs::exists(paths.three_dir / "three.module.js")) {
    spdlog::warn("three.js is missing ({}); the page cannot draw until libjs-three is installed",
                 (paths.three_dir / "three.module.js").string());
  }
  if (std::string e = check_http_spec(http, allow_remote); !e.empty()) {
    fmt::print(stderr, "bodyd-viewer-bridge: {}\n", e);
    return 2;
  }
  if (std::string e = ensure_descriptors(kDescriptorsNeeded); !e.empty()) {
    fmt::print(stderr, "bodyd-viewer-bridge: {}\n", e);
    return 2;
  }

  client::ClientOptions options;
  options.pose_endpoint = endpoint;
  options.control_endpoint = control == "none" ? "" : control;
  std::string error;
  auto poses = client::Client::connect(options, error);
  if (!poses) {
    fmt::print(stderr, "bodyd-viewer-bridge: pose endpoint {} ({}): {}\n", endpoint, endpoint_from, error);
    return 2;
  }
  // The control socket gets its own client: the pose thread never waits on a control request.
  std::unique_ptr<client::Client> control_client;
  if (!options.control_endpoint.empty()) {
    client::ClientOptions control_options = options;
    control_options.receive_hwm = 1;
    control_client = client::Client::connect(control_options, error);
    if (!control_client) {
      fmt::print(stderr, "bodyd-viewer-bridge: control endpoint {} ({}): {}\n", control, control_from, error);
      return 2;
    }
    protocol::SkeletonMessage skel;
    if (auto s = poses->skeleton(skel); !s) spdlog::warn("skeleton from {}: {}; waiting for it on the stream", control, s.error);
  }

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  signal(SIGPIPE, SIG_IGN);

  Bridge bridge(paths, endpoint, *poses, control_client.get(), options.control_endpoint, hold_load);
  mg_init_library(0);
  const std::string threads = std::to_string(kWorkerThreads);
  const std::string queue = std::to_string(kConnectionQueue);
  const std::string request_timeout = std::to_string(kRequestTimeoutMs);
  // websocket_timeout_ms with ping/pong: a page that sends nothing for 10 s is pinged (browsers
  // answer by themselves) and closed after CivetWeb's few unanswered pings; pings from the page
  // are answered with pongs. Empty access_control_* options: no CORS headers and no automatic
  // answer to a preflight (OPTIONS is then 405 like any other method).
  const char* mg_options[] = {"listening_ports", http.c_str(), "num_threads", threads.c_str(),
                              "connection_queue", queue.c_str(), "request_timeout_ms", request_timeout.c_str(),
                              "websocket_timeout_ms", "10000", "enable_websocket_ping_pong", "yes",
                              "enable_keep_alive", "no", "access_control_allow_origin", "",
                              "access_control_allow_methods", "", "access_control_allow_headers", "", nullptr};
  mg_callbacks callbacks{};
  callbacks.log_message = log_message;
  callbacks.begin_request = begin_request;
  callbacks.connection_close = connection_close;
  mg_context* ctx = mg_start(&callbacks, &bridge, mg_options);
  if (!ctx) {
    fmt::print(stderr, "bodyd-viewer-bridge: --http {}: cannot listen (another program on that port? pick another, or port 0)\n",
               http);
    mg_exit_library();
    return 2;
  }
  mg_set_websocket_handler(ctx, "/ws", ws_connect, ws_ready, ws_data, ws_close, &bridge);
  mg_set_request_handler(ctx, "**", request_handler, &bridge);
  mg_server_port ports[4];
  const int port_count = mg_get_server_ports(ctx, 4, ports);
  const int port = port_count > 0 ? ports[0].port : 0;
  const std::string http_host = http.substr(0, http.rfind(':'));
  bridge.set_access_policy(AccessPolicy{port});

  const std::string url = fmt::format("http://{}:{}/", http_host, port);
  fmt::print("bodyd-viewer-bridge: serving {} (poses from {}, status from {})\n", url, endpoint, control);
  std::fflush(stdout);
  std::thread pose_thread([&] { bridge.pose_thread(); });
  std::thread status_thread([&] { bridge.status_thread(); });
  std::thread push_thread([&] { bridge.push_thread(); });
  while (!g_stop.load()) std::this_thread::sleep_for(50ms);
  bridge.shared().changed.notify_all();
  bridge.close_websockets();
  stop_server(ctx, http_host, port);  // closes the WebSockets first: the push thread then writes to no one
  pose_thread.join();
  status_thread.join();
  push_thread.join();
  mg_exit_library();
  spdlog::info("stopped ({} poses received)", bridge.poses_received());
  return 0;
}
