#include "bodyd/base/loopback.h"

#include <arpa/inet.h>

#include <cstring>
#include <string>

namespace bodyd {

bool is_loopback(const in_addr& a) { return (ntohl(a.s_addr) >> 24) == 127; }

bool is_loopback(const in6_addr& a) {
  if (IN6_IS_ADDR_LOOPBACK(&a)) return true;
  if (!IN6_IS_ADDR_V4MAPPED(&a)) return false;
  in_addr v4{};
  std::memcpy(&v4.s_addr, a.s6_addr + 12, 4);
  return is_loopback(v4);
}

bool is_loopback(const sockaddr& a) {
  if (a.sa_family == AF_INET) return is_loopback(reinterpret_cast<const sockaddr_in&>(a).sin_addr);
  if (a.sa_family == AF_INET6) return is_loopback(reinterpret_cast<const sockaddr_in6&>(a).sin6_addr);
  return false;
}

bool is_loopback_host(std::string_view host) {
  if (host == "localhost") return true;
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  const std::string h(host);
  in_addr v4{};
  if (::inet_pton(AF_INET, h.c_str(), &v4) == 1) return is_loopback(v4);
  in6_addr v6{};
  if (::inet_pton(AF_INET6, h.c_str(), &v6) == 1) return is_loopback(v6);
  return false;
}

}  // namespace bodyd
