// The Unix-socket server loop of SlimeVR's framed protocols (framed_server.h).
#include "bodyd/io/slimevr/framed_server.h"

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
      c.last_frame_ns = arrival_ns;
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
    if (fd < 0) {
      if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM) {
        accept_paused_until_ns_ = monotonic_ns() + limits_.accept_backoff_ns;
        handler_.dropping(nullptr, FramedDrop::OutOfDescriptors, static_cast<std::size_t>(errno));
      }
      return;  // EAGAIN: all taken; ECONNABORTED: the peer went
    }
    if (connections_.size() >= limits_.max_connections) {
      // Evict the idlest, if it has been idle long enough (a client that connects and says
      // nothing must not lock the real driver out); else refuse the newcomer.
      const std::int64_t now = monotonic_ns();
      FramedConnection* idlest = nullptr;
      for (auto& c : connections_)
        if (!c->drop && (idlest == nullptr || c->last_frame_ns < idlest->last_frame_ns)) idlest = c.get();
      if (idlest == nullptr || now - idlest->last_frame_ns < limits_.evict_idle_after_ns) {
        ::close(fd);
        handler_.dropping(nullptr, FramedDrop::TooManyClients, 0);
        continue;
      }
      handler_.dropping(idlest, FramedDrop::IdleEvicted,
                        static_cast<std::size_t>((now - idlest->last_frame_ns) / 1'000'000'000));
      idlest->drop = true;
      close_dropped();
    }
    limit_send_buffer(fd, limits_.send_buffer_bytes);
    std::unique_ptr<FramedConnection> c = handler_.make_connection();
    c->fd = fd;
    c->number = ++accepted_;
    c->window_start_ns = monotonic_ns();
    c->last_frame_ns = c->window_start_ns;
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
      const bool paused = monotonic_ns() < accept_paused_until_ns_;
      fds.push_back({listen_fd_, static_cast<short>(paused ? 0 : POLLIN), 0});
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
    const std::int64_t now = monotonic_ns();
    wait_ms = std::clamp(handler_.tick(now), 0, 100);
    if (now < accept_paused_until_ns_)
      wait_ms = std::min(wait_ms, static_cast<int>((accept_paused_until_ns_ - now) / 1'000'000) + 1);
    // What the tick appended (a paced update, a status) goes out now.
    for (auto& c : connections_)
      if (!c->drop && !c->out.empty()) flush(*c);
    close_dropped();
  }
}

}  // namespace bodyd::drivers::slimevr
