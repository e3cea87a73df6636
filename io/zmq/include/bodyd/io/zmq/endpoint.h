// Which endpoints bodyd may bind, and ZeroMQ CURVE keys.
//
// Body motion identifies people, so by default bodyd binds only where nobody else on the
// network can connect: ipc:// (a Unix socket; bodyd creates its directory with mode 0700),
// inproc://, and TCP on a loopback address (127.0.0.0/8, localhost, [::1], the "lo"
// interface). Anything else (0.0.0.0, *, a LAN address, another transport) is refused unless
// the user asked for it with --allow-remote; then CURVE encryption (docs/daemon.md) should be
// configured too.
#pragma once

#include "bodyd/client/curve_keys.h"

#include <filesystem>
#include <string>
#include <string_view>

namespace bodyd::daemon {

// True for ipc://, inproc:// and loopback TCP endpoints.
[[nodiscard]] bool is_local_endpoint(std::string_view endpoint);

// Empty when `endpoint` may be bound; otherwise what is wrong and what to do. `what` names
// the socket in the message ("--pub", "--control").
[[nodiscard]] std::string check_bind_endpoint(std::string_view endpoint, bool allow_remote, std::string_view what);

// The directory of the default ipc:// endpoints (ipc:///tmp/bodyd/pose, .../control).
inline constexpr std::string_view kDefaultIpcDirectory = "/tmp/bodyd";

// For ipc:// endpoints: creates the socket's directory (mkdir mode 0700) if missing. That
// directory, and the default one (/tmp/bodyd) whether new or not, must be private: a real
// directory (not a symlink), owned by this user, no permissions for group or others;
// otherwise refused with what to do. Refuses a path that is a directory or any file other
// than a socket (bodyd never replaces a file), and a socket another process is listening on
// ("another bodyd running?"); a stale socket left by a crashed process is fine (ZeroMQ
// replaces it). Empty on success, else the error.
[[nodiscard]] std::string prepare_ipc_endpoint(std::string_view endpoint, std::string_view what);

// Empty when `dir` is a private directory: a directory (lstat: not a symlink), owned by the
// effective user, with no permission bits for group or others. Else what is wrong and what to do.
[[nodiscard]] std::string check_private_directory(const std::filesystem::path& dir);

// The address to pass to zmq_bind for an endpoint check_bind_endpoint accepted:
// "tcp://localhost:P" becomes "tcp://127.0.0.1:P" (ZeroMQ takes a bind host for an interface
// name); a bracketed IPv6 host ("tcp://[::1]:P") sets out_ipv6, and the socket needs ZMQ_IPV6
// set before binding. Other endpoints are returned as they are.
[[nodiscard]] std::string zmq_bind_address(std::string_view endpoint, bool& out_ipv6);

// A CURVE key pair, Z85 text (40 characters each).
struct CurveKeyPair {
  std::string public_key;
  std::string secret_key;
};

// Generates a key pair and writes DIR/NAME.public (0644) and DIR/NAME.secret (0600),
// refusing to overwrite existing files. NAME "server": bodyd's own pair; any other: a
// client's (its .public goes into a --curve-allow directory). Empty on success, else the error.
[[nodiscard]] std::string generate_curve_keys(const std::filesystem::path& dir, CurveKeyPair& out_keys,
                                              const std::string& name = "server");

// Reading key files, and the public key of a secret key: shared with the clients, which read
// the same files (client/include/bodyd/client/curve_keys.h).
using client::curve_public_from_secret;
using client::read_curve_key_file;

}  // namespace bodyd::daemon
