#include "osc_sender.h"

#include "bodyd/base/loopback.h"

#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>

namespace bodyd::daemon {

bool split_host_port(std::string_view target, std::string_view default_host, int default_port, std::string& out_host,
                     std::string& out_port, std::string_view what, std::string& error) {
  std::string_view host = target, port;
  if (!target.empty() && target.front() == '[') {  // [IPv6]:PORT
    const auto close = target.find(']');
    if (close == std::string_view::npos) {
      error = std::string(what) + ": \"" + std::string(target) + "\": missing ']' after an IPv6 address";
      return false;
    }
    host = target.substr(1, close - 1);
    const std::string_view rest = target.substr(close + 1);
    if (!rest.empty()) {
      if (rest.front() != ':') {
        error = std::string(what) + ": \"" + std::string(target) + "\": expected [ADDRESS]:PORT";
        return false;
      }
      port = rest.substr(1);
    }
  } else if (const auto colon = target.rfind(':'); colon != std::string_view::npos) {
    host = target.substr(0, colon);
    port = target.substr(colon + 1);
    if (host.find(':') != std::string_view::npos) {
      error = std::string(what) + ": \"" + std::string(target) + "\": write an IPv6 address in brackets, [::1]:PORT";
      return false;
    }
  }
  out_host = host.empty() ? std::string(default_host) : std::string(host);
  int port_number = default_port;
  if (!port.empty()) {
    const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), port_number);
    if (ec != std::errc() || end != port.data() + port.size() || port_number < 1 || port_number > 65535) {
      error = std::string(what) + ": port \"" + std::string(port) + "\" is not a UDP port number (1..65535)";
      return false;
    }
  }
  out_port = std::to_string(port_number);
  return true;
}

std::string OscSender::open(const std::string& host, const std::string& port, const std::string& what,
                            bool allow_many_receivers) {
  close();
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_protocol = IPPROTO_UDP;
  addrinfo* found = nullptr;
  if (const int rc = ::getaddrinfo(host.c_str(), port.c_str(), &hints, &found); rc != 0 || !found)
    return what + ": cannot resolve \"" + host + "\": " + ::gai_strerror(rc) + " (give an IP address, e.g. 127.0.0.1)";
  const addrinfo& a = *found;
  char text[INET6_ADDRSTRLEN] = {};
  if (a.ai_family == AF_INET) {
    const auto* in = reinterpret_cast<const sockaddr_in*>(a.ai_addr);
    ::inet_ntop(AF_INET, &in->sin_addr, text, sizeof(text));
    loopback_ = is_loopback(in->sin_addr);
    address_ = std::string(text) + ":" + port;
  } else {
    const auto* in6 = reinterpret_cast<const sockaddr_in6*>(a.ai_addr);
    ::inet_ntop(AF_INET6, &in6->sin6_addr, text, sizeof(text));
    loopback_ = is_loopback(in6->sin6_addr);
    address_ = "[" + std::string(text) + "]:" + port;
  }
  // Not one receiver's address (issue 20): refused like a broadcast address, whose refusal is
  // the kernel's (no SO_BROADCAST), unless the user consents with --allow-remote.
  const char* fan_out = nullptr;
  if (a.ai_family == AF_INET) {
    const std::uint32_t ip = ntohl(reinterpret_cast<const sockaddr_in*>(a.ai_addr)->sin_addr.s_addr);
    if (ip == INADDR_ANY) fan_out = "the unspecified address";
    else if (ip == INADDR_BROADCAST) fan_out = "the broadcast address";
    else if ((ip >> 28) == 0xE) fan_out = "a multicast address";
  } else {
    const auto& in6 = reinterpret_cast<const sockaddr_in6*>(a.ai_addr)->sin6_addr;
    if (IN6_IS_ADDR_UNSPECIFIED(&in6)) fan_out = "the unspecified address";
    else if (IN6_IS_ADDR_MULTICAST(&in6)) fan_out = "a multicast address";
  }
  if (fan_out && !allow_many_receivers) {
    ::freeaddrinfo(found);
    return what + ": " + address_ + " is " + fan_out +
           ", not one receiver's: refused, as a broadcast address is. Name the receiving app's address (127.0.0.1 "
           "when it runs on this machine), or give --allow-remote (config \"allow_remote\": true) to send there anyway";
  }
  fd_ = ::socket(a.ai_family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, IPPROTO_UDP);
  std::string error;
  if (fd_ >= 0 && allow_many_receivers && a.ai_family == AF_INET) {
    const int one = 1;  // with consent, broadcast addresses too (the kernel refuses them without it)
    ::setsockopt(fd_, SOL_SOCKET, SO_BROADCAST, &one, sizeof one);
  }
  if (fd_ < 0) error = what + ": socket: " + std::strerror(errno);
  // connect(): the kernel fixes the destination (sends go nowhere else) and reports "nothing
  // listens" (ICMP port unreachable) on a later send, which the output counts.
  else if (::connect(fd_, a.ai_addr, a.ai_addrlen) != 0)
    error = what + ": cannot send to " + address_ + ": " + std::strerror(errno) +
            (errno == EACCES ? " (a broadcast address? name one receiver's address, or give --allow-remote to send "
                               "there anyway)"
                             : "");
  ::freeaddrinfo(found);
  if (!error.empty()) {
    close();
    return error;
  }
  if (!loopback_)
    spdlog::warn("{}: sending body motion to {} over the network, unencrypted (OSC has no authentication or "
                 "encryption): anyone on the path can read it",
                 what, address_);
  return {};
}

bool OscSender::send(const void* data, std::size_t size, std::string& out_error) {
  if (fd_ < 0) {
    out_error = "not open";
    return false;
  }
  const ssize_t n = ::send(fd_, data, size, MSG_DONTWAIT | MSG_NOSIGNAL);
  if (n == static_cast<ssize_t>(size)) return true;
  const int err = n < 0 ? errno : EMSGSIZE;
  out_error = std::strerror(err);
  if (err == ECONNREFUSED) out_error += " (nothing listens on " + address_ + ": is the receiving app running, with OSC on?)";
  else if (err == EAGAIN || err == EWOULDBLOCK || err == ENOBUFS) out_error += " (the socket buffer is full: the pose is dropped)";
  return false;
}

bool OscSender::send_bundle(const std::vector<std::uint8_t>& bytes, std::string& out_error) {
  if (bytes.empty()) {
    out_error = "liblo could not serialise the bundle";
    return false;
  }
  if (!send(bytes.data(), bytes.size(), out_error)) return false;
  bundles_sent_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

void OscSender::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

OscBundle::OscBundle() : bundle_(lo_bundle_new(LO_TT_IMMEDIATE)) {}

OscBundle::~OscBundle() {
  if (bundle_) lo_bundle_free_recursive(bundle_);
}

int OscBundle::add_floats(const std::string& path, int float_count) {
  lo_message m = lo_message_new();
  for (int i = 0; i < float_count; ++i) lo_message_add_float(m, 0.0f);
  return add_message(path, m);
}

int OscBundle::add_message(const std::string& path, lo_message message) {
  paths_.push_back(path);
  lo_bundle_add_message(bundle_, paths_.back().c_str(), message);
  messages_.push_back(message);
  // The argument vector points into the message's data; it is built once here, and the
  // message gets no more arguments (which would reallocate the data).
  argv_.push_back(lo_message_get_argv(message));
  bytes_.clear();
  return static_cast<int>(messages_.size()) - 1;
}

const std::vector<std::uint8_t>& OscBundle::serialise() {
  if (bytes_.empty()) bytes_.resize(lo_bundle_length(bundle_));
  std::size_t size = bytes_.size();
  if (!lo_bundle_serialise(bundle_, bytes_.data(), &size) || size != bytes_.size()) bytes_.clear();
  return bytes_;
}

}  // namespace bodyd::daemon
