// The OSCQuery side's HTTP server (oscquery.h): a small poll()-based server of its own, one
// thread, read-only answers from a handler. Internal to vrchat/ (oscquery.cpp only).
#pragma once

#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace bodyd::drivers::detail::http {

// ---- the HTTP server ----------------------------------------------------------------------------------
// One thread, non-blocking sockets, poll(): an idle or slow connection costs a descriptor and a
// small buffer, never a worker (CivetWeb, used before, held a worker per connection, so five
// slowloris connections blocked it; it also spun on accept() when out of descriptors and took
// 2 s to stop; issue 20 items 4, 6, 7). The rules (docs/vr-apps.md, docs/reliability.md):
//   - a request's headers must arrive within kRequestTimeout of the connection, and its answer
//     leave within as long; then the connection is closed (one request per connection);
//   - at most kMaxConnections open, at most kMaxPerClient from one address; a connection beyond
//     either closes the oldest one (of that address, or of all), so a client that holds
//     connections open cannot lock out one that asks and goes;
//   - out of descriptors, accept() is retried after a back-off (100 ms doubling to 1 s) instead
//     of at once, the oldest connection is closed to free one, and the log says so once;
//   - stop() wakes the thread through an eventfd: it returns at once.

inline constexpr std::chrono::milliseconds kRequestTimeout{2000};
inline constexpr std::size_t kMaxConnections = 32;
inline constexpr std::size_t kMaxPerClient = 16;
inline constexpr std::size_t kMaxRequestBytes = 8192;

struct HttpResponse {
  int status = 200;
  std::string content_type = "application/json";
  std::string body;
};

inline const char* reason(int status) {
  switch (status) {
    case 200: return "OK";
    case 204: return "No Content";
    case 400: return "Bad Request";
    case 403: return "Forbidden";
    case 404: return "Not Found";
    case 405: return "Method Not Allowed";
    case 431: return "Request Header Fields Too Large";
    default: return "Error";
  }
}

inline std::string ascii_lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// Host names an OSCQuery client may use for us: an IP address (what mDNS resolves to, and what
// VRChat connects to), "localhost", or an mDNS name (*.local). Any other name is a page's own
// domain resolved to us (DNS rebinding) and is refused. No Host (HTTP/1.0) is no browser: allowed.
inline bool host_allowed(std::string_view host) {
  std::string name(host);
  if (!host.empty() && host.front() == '[') {
    const std::size_t close = host.find(']');
    if (close == std::string_view::npos) return false;
    in6_addr a6{};
    return ::inet_pton(AF_INET6, std::string(host.substr(1, close - 1)).c_str(), &a6) == 1;
  }
  if (const std::size_t colon = host.rfind(':'); colon != std::string_view::npos) name = host.substr(0, colon);
  name = ascii_lower(name);
  if (!name.empty() && name.back() == '.') name.pop_back();
  in_addr a4{};
  return name == "localhost" || ::inet_pton(AF_INET, name.c_str(), &a4) == 1 ||
         (name.size() > 6 && name.ends_with(".local"));
}

// "%2F" and the like decoded; false for a bad escape.
inline bool percent_decode(std::string_view in, std::string& out) {
  out.clear();
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (in[i] != '%') {
      out += in[i];
      continue;
    }
    if (i + 2 >= in.size() || !std::isxdigit(static_cast<unsigned char>(in[i + 1])) ||
        !std::isxdigit(static_cast<unsigned char>(in[i + 2])))
      return false;
    out += static_cast<char>(std::stoi(std::string(in.substr(i + 1, 2)), nullptr, 16));
    i += 2;
  }
  return true;
}

class HttpServer {
 public:
  // method, decoded path, query: the answer (GET and HEAD only reach it).
  using Handler = std::function<HttpResponse(const std::string& path, const std::string& query)>;

  explicit HttpServer(Handler handler) : handler_(std::move(handler)) {}
  ~HttpServer() { stop(); }

  // Listens on host (IPv4, "0.0.0.0" for every interface) at a free port. Empty or the error.
  std::string start(const std::string& host) {
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    if (::inet_pton(AF_INET, host.c_str(), &addr.sin_addr) != 1) return "'" + host + "' is not an IPv4 address";
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (listen_fd_ < 0) return std::string("socket(): ") + std::strerror(errno);
    const int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (::bind(listen_fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0 || ::listen(listen_fd_, 64) != 0)
      return "cannot listen on " + host + ":0: " + std::strerror(errno);
    socklen_t len = sizeof addr;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (wake_fd_ < 0) return std::string("eventfd(): ") + std::strerror(errno);
    thread_ = std::thread([this] { loop(); });
    return {};
  }

  void stop() {
    if (thread_.joinable()) {
      const std::uint64_t one = 1;
      (void)!::write(wake_fd_, &one, sizeof one);
      thread_.join();
    }
    for (Connection& c : connections_) ::close(c.fd);
    connections_.clear();
    if (listen_fd_ >= 0) ::close(listen_fd_);
    if (wake_fd_ >= 0) ::close(wake_fd_);
    listen_fd_ = wake_fd_ = -1;
  }

  [[nodiscard]] int port() const { return port_; }

 private:
  using Clock = std::chrono::steady_clock;

  struct Connection {
    int fd = -1;
    std::string peer;        // the client's address, without port
    std::string in, out;     // request bytes so far; the answer
    std::size_t sent = 0;
    bool answering = false;  // the answer is being sent
    Clock::time_point deadline;
    std::uint64_t order = 0;  // accept order: the smallest is the oldest
  };

  void loop() {
    std::vector<pollfd> fds;
    Clock::time_point accept_paused_until{};
    std::chrono::milliseconds backoff{100};
    for (;;) {
      const Clock::time_point now = Clock::now();
      const bool accepting = now >= accept_paused_until;
      fds.clear();
      fds.push_back({wake_fd_, POLLIN, 0});
      fds.push_back({accepting ? listen_fd_ : -1, POLLIN, 0});
      Clock::time_point next = accepting ? Clock::time_point::max() : accept_paused_until;
      for (const Connection& c : connections_) {
        fds.push_back({c.fd, static_cast<short>(c.answering ? POLLOUT : POLLIN), 0});
        next = std::min(next, c.deadline);
      }
      int timeout_ms = -1;
      if (next != Clock::time_point::max())
        timeout_ms = static_cast<int>(std::clamp<std::int64_t>(
            std::chrono::duration_cast<std::chrono::milliseconds>(next - now).count() + 1, 0, 60000));
      if (::poll(fds.data(), fds.size(), timeout_ms) < 0 && errno != EINTR) {
        spdlog::error("OSCQuery HTTP: poll(): {}; the server stops", std::strerror(errno));
        return;
      }
      if (fds[0].revents) return;  // stop()
      const Clock::time_point after = Clock::now();
      // Connections first (fds[2..] match connections_ as it was), then new ones.
      std::vector<bool> done(connections_.size(), false);
      for (std::size_t i = 0; i < connections_.size(); ++i) {
        Connection& c = connections_[i];
        if (fds[i + 2].revents) done[i] = !serve(c);
        if (!done[i] && after >= c.deadline) done[i] = true;  // too slow: closed unanswered
      }
      for (std::size_t i = connections_.size(); i-- > 0;)
        if (done[i]) close_at(i);
      if (accepting && (fds[1].revents & POLLIN)) {
        if (accept_all(after)) {
          backoff = std::chrono::milliseconds(100);
        } else {
          accept_paused_until = after + backoff;
          backoff = std::min(backoff * 2, std::chrono::milliseconds(1000));
        }
      }
    }
  }

  // Accepts what is waiting. False when out of descriptors (the caller backs off).
  bool accept_all(Clock::time_point now) {
    for (int i = 0; i < 64; ++i) {
      sockaddr_in peer{};
      socklen_t len = sizeof peer;
      const int fd = ::accept4(listen_fd_, reinterpret_cast<sockaddr*>(&peer), &len, SOCK_NONBLOCK | SOCK_CLOEXEC);
      if (fd < 0) {
        if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM) {
          if (!exhaustion_logged_) {
            exhaustion_logged_ = true;
            rlimit limit{};
            ::getrlimit(RLIMIT_NOFILE, &limit);
            spdlog::warn("OSCQuery HTTP: out of file descriptors ({}; the limit is {}, ulimit -n): new connections wait "
                         "and the oldest open one is closed; raise the limit if this is not an attack (logged once)",
                         std::strerror(errno), static_cast<long long>(limit.rlim_cur));
          }
          if (!connections_.empty()) close_at(oldest([](const Connection&) { return true; }));
          return false;
        }
        return true;  // EAGAIN (all taken), or the peer went (ECONNABORTED): nothing to do
      }
      char text[INET_ADDRSTRLEN] = "?";
      ::inet_ntop(AF_INET, &peer.sin_addr, text, sizeof text);
      const std::string address = text;
      const std::size_t same = static_cast<std::size_t>(std::count_if(
          connections_.begin(), connections_.end(), [&](const Connection& c) { return c.peer == address; }));
      if (same >= kMaxPerClient) {
        close_at(oldest([&](const Connection& c) { return c.peer == address; }));
      } else if (connections_.size() >= kMaxConnections) {
        close_at(oldest([](const Connection&) { return true; }));
      }
      connections_.push_back({fd, address, {}, {}, 0, false, now + kRequestTimeout, next_order_++});
    }
    return true;
  }

  template <class Pred>
  std::size_t oldest(Pred pred) const {
    std::size_t best = connections_.size();
    for (std::size_t i = 0; i < connections_.size(); ++i)
      if (pred(connections_[i]) && (best == connections_.size() || connections_[i].order < connections_[best].order)) best = i;
    return best;
  }

  void close_at(std::size_t i) {
    if (i >= connections_.size()) return;
    ::close(connections_[i].fd);
    connections_.erase(connections_.begin() + static_cast<std::ptrdiff_t>(i));
  }

  // Reads or writes what the socket allows. False when the connection is finished.
  bool serve(Connection& c) {
    if (c.answering) {
      while (c.sent < c.out.size()) {
        const ssize_t n = ::send(c.fd, c.out.data() + c.sent, c.out.size() - c.sent, MSG_NOSIGNAL);
        if (n < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
        c.sent += static_cast<std::size_t>(n);
      }
      ::shutdown(c.fd, SHUT_WR);
      return false;
    }
    char buffer[2048];
    for (;;) {
      const ssize_t n = ::recv(c.fd, buffer, sizeof buffer, 0);
      if (n == 0) return false;  // the client went before asking
      if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) break;
        return false;
      }
      c.in.append(buffer, static_cast<std::size_t>(n));
      if (c.in.size() > kMaxRequestBytes) break;
    }
    std::size_t end = c.in.find("\r\n\r\n");
    if (end == std::string::npos && c.in.size() <= kMaxRequestBytes) return true;  // more to come
    if (end != std::string::npos && end > kMaxRequestBytes) end = std::string::npos;
    bool head = false;
    const HttpResponse r = end == std::string::npos
                               ? HttpResponse{431, "text/plain", "request headers over 8 KiB"}
                               : answer(std::string_view(c.in).substr(0, end), head);
    c.out = "HTTP/1.1 " + std::to_string(r.status) + " " + reason(r.status) + "\r\n";
    if (r.status != 204) c.out += "Content-Type: " + r.content_type + "\r\nContent-Length: " + std::to_string(r.body.size()) + "\r\n";
    c.out += "Cache-Control: no-store\r\nConnection: close\r\n\r\n";
    if (!head && r.status != 204) c.out += r.body;
    c.answering = true;
    c.deadline = Clock::now() + kRequestTimeout;
    return serve(c);
  }

  // The answer to one request's head (request line and headers, without the blank line).
  HttpResponse answer(std::string_view request, bool& out_head) const {
    const std::size_t line_end = request.find("\r\n");
    const std::string_view line = request.substr(0, line_end);
    const std::size_t sp1 = line.find(' '), sp2 = line.rfind(' ');
    if (sp1 == std::string_view::npos || sp2 == sp1 || line.substr(sp2 + 1).rfind("HTTP/1.", 0) != 0)
      return {400, "text/plain", "not an HTTP/1.x request line"};
    const std::string_view method = line.substr(0, sp1), target = line.substr(sp1 + 1, sp2 - sp1 - 1);
    // Headers: only Host matters.
    std::size_t at = line_end == std::string_view::npos ? request.size() : line_end + 2;
    while (at < request.size()) {
      std::size_t next = request.find("\r\n", at);
      if (next == std::string_view::npos) next = request.size();
      const std::string_view header = request.substr(at, next - at);
      at = next + 2;
      const std::size_t colon = header.find(':');
      if (colon == std::string_view::npos || ascii_lower(header.substr(0, colon)) != "host") continue;
      std::string_view value = header.substr(colon + 1);
      while (!value.empty() && (value.front() == ' ' || value.front() == '\t')) value.remove_prefix(1);
      while (!value.empty() && (value.back() == ' ' || value.back() == '\t')) value.remove_suffix(1);
      if (!host_allowed(value))
        return {403, "text/plain", "Host must be an IP address, localhost or an mDNS .local name"};
    }
    out_head = method == "HEAD";
    if (method != "GET" && method != "HEAD") return {405, "text/plain", "only GET is served"};
    const std::size_t q = target.find('?');
    std::string path;
    if (!percent_decode(target.substr(0, q), path) || path.empty() || path.front() != '/')
      return {400, "text/plain", "bad request target"};
    return handler_(path, q == std::string_view::npos ? std::string() : std::string(target.substr(q + 1)));
  }

  Handler handler_;
  int listen_fd_ = -1, wake_fd_ = -1, port_ = 0;
  std::thread thread_;
  std::vector<Connection> connections_;  // the server thread's
  std::uint64_t next_order_ = 0;
  bool exhaustion_logged_ = false;
};

}  // namespace bodyd::drivers::detail::http
