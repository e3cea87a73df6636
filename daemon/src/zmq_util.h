// ZeroMQ pieces the pose publisher and the control socket share: an owned context and
// socket (RAII), binding with bodyd's endpoint policy (endpoint.h), and CURVE server keys.
#pragma once

#include "bodyd/base/non_copyable.h"

#include <memory>
#include <string>

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

}  // namespace bodyd::daemon
