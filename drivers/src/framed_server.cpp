// The Unix-socket server loop of SlimeVR's framed protocols (framed_server.h).
#include "bodyd/drivers/framed_server.h"

#include "bodyd/base/clock.h"

#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace bodyd::drivers::slimevr {

FramedServer::FramedServer(std::string path, FramedServerLimits limits, FramedHandler& handler)
    : path_(std::move(path)), limits_(limits), handler_(handler), read_buf_(limits.read_chunk_bytes) {}

FramedServer::~FramedServer() { stop(); }

std::string FramedServer::start() {
  if (listen_fd_ >= 0) return {};
  std::string e;
  const int fd = listen_unix(path_, e);
  if (fd < 0) return e;
  const int wake = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake < 0) {
    ::close(fd);
    return std::string("eventfd: ") + std::strerror(errno);
  }
  listen_fd_ = fd;
  wake_fd_ = wake;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
  return {};
}

void FramedServer::stop() {
  stop_.store(true);
  if (thread_.joinable()) {
    wake();
    thread_.join();
  }
  std::lock_guard lock(mutex_);
  for (auto& c : connections_) {
    handler_.closing(*c, 0, true);
    ::close(c->fd);
  }
  connections_.clear();
  if (listen_fd_ >= 0) {
    ::close(listen_fd_);
    listen_fd_ = -1;
    ::unlink(path_.c_str());
  }
  if (wake_fd_ >= 0) ::close(wake_fd_), wake_fd_ = -1;
}

void FramedServer::wake() const {
  if (wake_fd_ < 0) return;
  const std::uint64_t one = 1;
  (void)!::write(wake_fd_, &one, sizeof one);
}

void FramedServer::flush(FramedConnection& c) {
  while (!c.out.empty() && !c.drop) {
    const ssize_t n = ::send(c.fd, c.out.data(), c.out.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n > 0) {
      c.out.erase(c.out.begin(), c.out.begin() + n);
      continue;
    }
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
    if (n < 0 && errno == EINTR) continue;
    c.drop = true;  // EPIPE, ECONNRESET: gone; the thread closes it
    handler_.disconnected(c);
    return;
  }
  if (c.out.size() > limits_.max_pending_out_bytes) {
    handler_.dropping(&c, FramedDrop::SlowReader, c.out.size());
    c.drop = true;
  }
}

// Reads what is there and hands every whole frame to the handler; marks the connection for
// dropping on a broken stream, a flood or EOF.
void FramedServer::read(FramedConnection& c) {
  std::vector<std::uint8_t>& buf = read_buf_;
  for (int reads = 0; reads < 16 && !c.drop; ++reads) {
    const ssize_t n = ::recv(c.fd, buf.data(), buf.size(), MSG_DONTWAIT);
    if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
      c.drop = true;
      handler_.disconnected(c);
      return;
    }
    if (n < 0) return;
    const std::int64_t arrival_ns = monotonic_ns();
    c.in.insert(c.in.end(), buf.data(), buf.data() + n);
    std::size_t at = 0;
    while (!c.drop) {
      const FrameView f = next_frame(c.in.data() + at, c.in.size() - at, limits_.max_frame_bytes);
      if (f.result == FrameResult::NeedMore) break;
      if (f.result != FrameResult::Frame) {
        handler_.dropping(&c, f.result == FrameResult::TooLong ? FramedDrop::FrameTooLong : FramedDrop::FrameTooShort,
                          f.declared_bytes);
        c.drop = true;
        break;
      }
      at += f.frame_bytes;
      ++frames_in_;
      if (arrival_ns - c.window_start_ns >= 1'000'000'000) {
        c.window_start_ns = arrival_ns;
        c.window_frames = 0;
      }
      if (++c.window_frames > limits_.max_frames_per_second) {
        handler_.dropping(&c, FramedDrop::Flood, 0);
        c.drop = true;
        break;
      }
      handler_.frame(c, f.payload, f.payload_bytes, arrival_ns);
    }
    c.in.erase(c.in.begin(), c.in.begin() + static_cast<std::ptrdiff_t>(std::min(at, c.in.size())));
  }
}

void FramedServer::accept_all() {
  for (;;) {
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) return;
    if (connections_.size() >= limits_.max_connections) {
      ::close(fd);
      handler_.dropping(nullptr, FramedDrop::TooManyClients, 0);
      continue;
    }
    limit_send_buffer(fd, limits_.send_buffer_bytes);
    std::unique_ptr<FramedConnection> c = handler_.make_connection();
    c->fd = fd;
    c->number = ++accepted_;
    c->window_start_ns = monotonic_ns();
    handler_.accepted(*c);
    connections_.push_back(std::move(c));
  }
}

void FramedServer::close_dropped() {
  for (auto it = connections_.begin(); it != connections_.end();) {
    if (!(*it)->drop) {
      ++it;
      continue;
    }
    handler_.closing(**it, connections_.size() - 1, false);
    ::close((*it)->fd);
    it = connections_.erase(it);
  }
}

void FramedServer::run() {
  std::vector<pollfd> fds;
  int wait_ms = 0;
  while (!stop_.load()) {
    fds.clear();
    {
      std::lock_guard lock(mutex_);
      fds.push_back({listen_fd_, POLLIN, 0});
      fds.push_back({wake_fd_, POLLIN, 0});
      for (const auto& c : connections_)
        fds.push_back({c->fd, static_cast<short>(POLLIN | (c->out.empty() ? 0 : POLLOUT)), 0});
    }
    if (::poll(fds.data(), fds.size(), wait_ms) < 0 && errno != EINTR) break;
    std::lock_guard lock(mutex_);
    if (fds[1].revents & POLLIN) {
      std::uint64_t v;
      (void)!::read(wake_fd_, &v, sizeof v);
    }
    // Connections may have changed between the two locks (the owner drops only by flag), so
    // match by fd.
    for (std::size_t i = 2; i < fds.size(); ++i) {
      if (fds[i].revents == 0) continue;
      for (auto& c : connections_) {
        if (c->fd != fds[i].fd || c->drop) continue;
        if (fds[i].revents & (POLLIN | POLLHUP | POLLERR)) read(*c);
        if (!c->drop && !c->out.empty()) flush(*c);
      }
    }
    if (fds[0].revents & POLLIN) accept_all();
    close_dropped();
    wait_ms = std::clamp(handler_.tick(monotonic_ns()), 0, 100);
    // What the tick appended (a paced update, a status) goes out now.
    for (auto& c : connections_)
      if (!c->drop && !c->out.empty()) flush(*c);
    close_dropped();
  }
}

}  // namespace bodyd::drivers::slimevr
