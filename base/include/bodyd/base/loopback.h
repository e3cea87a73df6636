// The loopback rule (docs/daemon.md, "--allow-remote"): bodyd binds and sends to loopback
// addresses only, unless the user passes --allow-remote. One rule for every socket (ZeroMQ
// endpoints, OSC outputs, the network sources, the viewer bridge): an address is loopback when it
// is IPv4 127.0.0.0/8, IPv6 ::1, or an IPv4-mapped IPv6 address of 127.0.0.0/8
// (::ffff:127.0.0.1). By name, "localhost" is loopback (it is what bodyd resolves it to); any
// other name is not, whatever it resolves to, until it is resolved and its address checked.
#pragma once

#include <netinet/in.h>
#include <sys/socket.h>

#include <string_view>

namespace bodyd {

[[nodiscard]] bool is_loopback(const in_addr& a);
[[nodiscard]] bool is_loopback(const in6_addr& a);
// An AF_INET or AF_INET6 address; false for any other family.
[[nodiscard]] bool is_loopback(const sockaddr& a);
// A host as written: an IPv4 or IPv6 literal (the IPv6 one with or without [brackets]) or "localhost".
[[nodiscard]] bool is_loopback_host(std::string_view host);

}  // namespace bodyd
