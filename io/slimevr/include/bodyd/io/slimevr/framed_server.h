// The Unix-socket server of SlimeVR's framed protocols: one listening socket, its connections
// and one thread that accepts, reads whole frames (slimevr_bridge.h's framing: a uint32
// little-endian length that counts its own 4 bytes, then the payload) and writes what is
// waiting. Used by the SlimeVR bridge (BridgeServer, slimevr_bridge.cpp) and by the SolarXR
// server of the monado output (io/solarxr/output_monado.cpp); what each does with a frame, and
// how it counts and words a drop, is its FramedHandler's.
//
// Threading: the server's thread calls the handler with mutex() held. The owner takes mutex()
// for anything it shares with the handler and for connections() and flush(), which must be
// called with it held (e.g. to publish from another thread: append to a connection's `out`,
// then flush(); what the socket does not take now the thread writes when it is writable).
#pragma once

#include "bodyd/base/non_copyable.h"
#include "bodyd/io/slimevr/slimevr_bridge.h"

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace bodyd::drivers::slimevr {

// One client. A handler that keeps state per client derives from it (make_connection).
struct FramedConnection {
  virtual ~FramedConnection() = default;
  int fd = -1;
  std::uint64_t number = 0;  // 1, 2, ... in the order of connection (logs)
  std::vector<std::uint8_t> in, out;
  std::int64_t window_start_ns = 0;  // the flood check's one-second window
  std::uint32_t window_frames = 0;
  std::int64_t last_frame_ns = 0;    // its last whole frame (or its accept): the idlest is evicted first
  bool drop = false;  // closed by the thread at the end of its round
};

struct FramedServerLimits {
  std::size_t max_frame_bytes = kMaxFrameBytes;            // a longer frame breaks the stream: dropped
  std::size_t max_connections = kMaxConnections;           // more at once are refused
  std::size_t max_pending_out_bytes = kMaxPendingOutBytes;  // a client that reads nothing is dropped past this
  int send_buffer_bytes = kSendBufferBytes;                // SO_SNDBUF of each connection
  std::uint32_t max_frames_per_second = kMaxFramesPerSecond;  // a client sending more is dropped
  std::size_t read_chunk_bytes = 4096;                     // one recv()
  // When max_connections are open, a new client evicts the one whose last frame is oldest, if
  // that is at least this long ago; else the new one is refused.
  std::int64_t evict_idle_after_ns = 2'000'000'000;
  // Out of file descriptors, accepting pauses this long (the listening socket stays readable,
  // so retrying at once would spin).
  std::int64_t accept_backoff_ns = 100'000'000;
};

// Why the server drops a connection (or refuses one) on its own.
enum class FramedDrop : std::uint8_t {
  FrameTooLong,    // a frame declares more than max_frame_bytes (`bytes`: what it declares)
  FrameTooShort,   // a frame declares less than its 4 length bytes (`bytes`: what it declares)
  Flood,           // more than max_frames_per_second frames in a second
  SlowReader,      // more than max_pending_out_bytes waiting (`bytes`: how many)
  TooManyClients,  // max_connections already, none idle (no connection: refused before it is one)
  IdleEvicted,     // the idlest of max_connections, evicted for a new client (`bytes`: seconds idle)
  OutOfDescriptors,  // accept() failed with EMFILE / ENFILE (no connection; `bytes`: errno): paused
};

// What the owner does with the server's events; every call is made with the server's mutex held.
class FramedHandler {
 public:
  virtual ~FramedHandler() = default;
  // A new connection object (a derived one for per-client state).
  [[nodiscard]] virtual std::unique_ptr<FramedConnection> make_connection() { return std::make_unique<FramedConnection>(); }
  // Accepted, before it joins connections() (whose size does not count it yet).
  virtual void accepted(FramedConnection& c) { (void)c; }
  // One whole frame's payload, valid during the call; `arrival_ns` is when its bytes were read.
  virtual void frame(FramedConnection& c, const std::uint8_t* payload, std::size_t size, std::int64_t arrival_ns) = 0;
  // The client closed the connection, or its socket failed (EOF, ECONNRESET, EPIPE).
  virtual void disconnected(FramedConnection& c) { (void)c; }
  // The server drops `c` (nullptr for TooManyClients) for `why`.
  virtual void dropping(FramedConnection* c, FramedDrop why, std::size_t bytes) = 0;
  // `c` is closed: a dropped one at the end of a round (`remaining`: how many stay), or every
  // one by stop() (`stopping`).
  virtual void closing(FramedConnection& c, std::size_t remaining, bool stopping) {
    (void)c, (void)remaining, (void)stopping;
  }
  // Once a round of the server's thread (after what arrived was read), for work on the handler's
  // own clock: samples held back, paced updates, repeated statuses. Returns how many
  // milliseconds it may wait before the next call (the thread waits at most 100 ms anyway).
  [[nodiscard]] virtual int tick(std::int64_t now_ns) {
    (void)now_ns;
    return 100;
  }
};

class FramedServer : NonCopyable {
 public:
  FramedServer(std::string path, FramedServerLimits limits, FramedHandler& handler);
  ~FramedServer();  // stop()

  [[nodiscard]] const std::string& path() const { return path_; }
  // Binds and listens (listen_unix) and starts the thread. Empty, or what is wrong (not yet
  // naming the path). May be called with mutex() held; a running server is left as it is.
  [[nodiscard]] std::string start();
  // Joins the thread, closes every connection (handler.closing(c, 0, true)), the socket and
  // removes its file. Call it without mutex() held; idempotent.
  void stop();
  [[nodiscard]] bool running() const { return listen_fd_ >= 0; }

  [[nodiscard]] std::mutex& mutex() const { return mutex_; }
  // With mutex() held.
  [[nodiscard]] const std::vector<std::unique_ptr<FramedConnection>>& connections() const { return connections_; }
  // Writes what `c.out` holds and the socket takes now; drops `c` when too much is left. With
  // mutex() held.
  void flush(FramedConnection& c);
  // Frames read since start (those of a flood included). With mutex() held.
  [[nodiscard]] std::uint64_t frames_in() const { return frames_in_; }
  // Wakes the thread (it then polls for writability of what is waiting).
  void wake() const;

 private:
  void run();
  void read(FramedConnection& c);
  void accept_all();
  void close_dropped();

  std::string path_;
  FramedServerLimits limits_;
  FramedHandler& handler_;
  std::vector<std::uint8_t> read_buf_;  // the thread's
  int listen_fd_ = -1, wake_fd_ = -1;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  mutable std::mutex mutex_;  // what follows, and the handler's state
  std::vector<std::unique_ptr<FramedConnection>> connections_;
  std::uint64_t accepted_ = 0, frames_in_ = 0;
  std::int64_t accept_paused_until_ns_ = 0;  // out of descriptors: the listening socket rests until then
};

}  // namespace bodyd::drivers::slimevr
