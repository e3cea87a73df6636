// Loopback sockets for tests: a raw TCP connection, a port free right now.
#pragma once

#include <sys/socket.h>

namespace bodyd::test {

// A TCP connection to 127.0.0.1:port (blocking); -1 when it cannot connect. The caller closes it.
[[nodiscard]] int connect_loopback(int port);
// A 127.0.0.1 port of `type` (SOCK_DGRAM, SOCK_STREAM) free right now: bound, read, released,
// for a child process to bind a moment later.
[[nodiscard]] int free_loopback_port(int type = SOCK_DGRAM);

}  // namespace bodyd::test
