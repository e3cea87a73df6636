// ZeroMQ pieces the pose publisher and the control socket share: an owned context and
// socket (RAII), binding with bodyd's endpoint policy (endpoint.h), and CURVE server keys.
#pragma once

#include "bodyd/base/non_copyable.h"

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace bodyd::daemon {

class ZapAllowList;

std::string zmq_error_text();

// A ZeroMQ context and one socket of it, closed (socket, then context) on destruction.
class ZmqSocket : NonCopyable {
 public:
  ZmqSocket();
  ~ZmqSocket();

  // Creates the context and a socket of `type` (ZMQ_XPUB, ZMQ_REP). Empty or the error.
  [[nodiscard]] std::string open(int type, const char* type_name);
  void close();
  [[nodiscard]] void* get() const { return socket_; }
  [[nodiscard]] void* context() const { return context_; }

  // --curve-allow DIR: a ZAP handler in this socket's context accepts only the CURVE client
  // keys of DIR (curve_allow.h). Call after open(), before binding. Empty or the error.
  [[nodiscard]] std::string allow_only_keys_in(const std::string& dir);

 private:
  void* context_ = nullptr;
  void* socket_ = nullptr;
  std::unique_ptr<ZapAllowList> zap_;  // stopped after the socket closes, before the context ends
};

// Makes `socket` a CURVE server with the secret key in `secret_key_file` ("" = no CURVE).
// Sets out_public_key (Z85) when on. Empty or the error.
[[nodiscard]] std::string set_curve_server(void* socket, const std::string& secret_key_file, std::string& out_public_key);

// Binds with bodyd's policy (loopback unless allow_remote; ipc directory 0700) and warns when
// a non-loopback endpoint has no CURVE. `what` names the flag ("--pub", "--control").
// out_bound: the endpoint as bound (a port of * resolved). Empty or the error.
[[nodiscard]] std::string bind_socket(void* socket, const std::string& endpoint, const std::string& what, bool allow_remote,
                                      bool curve_on, std::string& out_bound);

// Descriptors open in this process now (/proc/self/fd), or 0 when unknown.
[[nodiscard]] std::size_t descriptors_open();
// How many connections a server may hold: a quarter of the descriptors free now (RLIMIT_NOFILE
// less those open), within [min, max]; `max` when the limit is unknown or infinite. The caps of
// every server together then stay under the limit, so no accept() meets EMFILE (libzmq 4.3's
// ipc listener aborts the process on it: ipc_listener.cpp's errno_assert).
[[nodiscard]] std::size_t connection_cap(std::size_t min, std::size_t max);
// Whether `fd` is still one of this socket's stream connections (not closed and reused by
// another file since its event): a SOCK_STREAM of the bound endpoint's family.
[[nodiscard]] bool is_connection_of(int fd, const std::string& bound_endpoint);

// Reads every event waiting on a socket monitor's receiving end (at most 1000), without blocking:
// on_event(ZMQ_EVENT_* id, value: a descriptor or errno).
void drain_monitor(void* pair, const std::function<void(std::uint16_t event, std::uint32_t value)>& on_event);

// Caps one ZeroMQ socket's connections, on a thread of its own that reads the socket's monitor
// (zmq_socket_monitor: ACCEPTED, ACCEPT_FAILED, DISCONNECTED). libzmq 4.3 accepts every
// connection that arrives and, in an ipc:// listener, aborts the process when accept() meets
// EMFILE (ipc_listener.cpp's errno_assert), so idle clients of one endpoint could take every
// descriptor and then kill bodyd (issue 43 item 6). The guard:
//   - refuses (shuts down) each connection beyond `max_connections`;
//   - for an ipc:// endpoint, hides its socket file (renamed to FILE.full) while the cap is
//     reached, so new clients get ENOENT instead of a connection, and restores it when one
//     leaves (the socket's ZMQ_BACKLOG bounds how many were already queued);
//   - out of descriptors (a tcp:// accept that failed), closes the newest connection.
class ConnectionGuard : NonCopyable {
 public:
  ~ConnectionGuard();
  // Call after the socket's options and before its bind. `what` names it in the log ("--pub").
  // Empty or the error.
  [[nodiscard]] std::string start(void* context, void* socket, const std::string& what, std::size_t max_connections);
  // The endpoint as bound (for ipc://, the file it hides while full). Call once bound.
  void set_bound(const std::string& bound_endpoint);
  // Joins the thread, puts a hidden socket file back; call before the socket closes.
  void stop();
  [[nodiscard]] std::size_t max_connections() const { return max_; }
  [[nodiscard]] std::uint64_t refused() const { return refused_.load(std::memory_order_relaxed); }

 private:
  void run();
  void on_event(std::uint16_t event, std::uint32_t value);
  void refuse(int fd);
  void gate();

  void* socket_ = nullptr;
  void* pair_ = nullptr;
  std::string what_;
  std::size_t max_ = 64;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;  // bound_ between set_bound() and the thread
  std::string bound_, ipc_path_;
  bool hidden_ = false, cap_logged_ = false, exhaustion_logged_ = false;
  std::vector<int> peers_;  // the thread's: connections, oldest first
  std::atomic<std::uint64_t> refused_{0};
};

}  // namespace bodyd::daemon
