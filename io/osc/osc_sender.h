// Sending OSC over UDP, shared by the OSC outputs (vrchat, vmc; docs/outputs.md).
//
// OscSender: one UDP socket connected to the address the user named (resolved once, at
// open()), sending with MSG_DONTWAIT: a send never blocks the reconstruction thread; a full
// socket buffer or an ICMP "port unreachable" from an earlier datagram (nothing listens) is
// returned as a failure for the caller to count, never retried. An address that is not one
// receiver's (broadcast, multicast 224.0.0.0/4 or ff00::/8, unspecified 0.0.0.0 or ::) is
// refused unless the user consents (--allow-remote): a broadcast address by the kernel (no
// SO_BROADCAST without consent), the others by open().
//
// OscBundle: an OSC bundle built once with liblo (its messages, paths and type tags fixed),
// whose numeric arguments are rewritten in place for each pose and serialised into a
// buffer owned by the bundle: the per-pose path does not allocate.
#pragma once

#include "bodyd/base/non_copyable.h"

#include <lo/lo_lowlevel.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <deque>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::daemon {

// Splits "HOST:PORT", "[V6]:PORT", "HOST" or "" (defaults fill the missing parts). False with
// `error` (naming `what`) when the port is not 1..65535 or the host is empty.
[[nodiscard]] bool split_host_port(std::string_view target, std::string_view default_host, int default_port,
                                   std::string& out_host, std::string& out_port, std::string_view what, std::string& error);

class OscSender : NonCopyable {
 public:
  OscSender() = default;
  ~OscSender() { close(); }

  // Resolves host:port (numeric or a name, IPv4 or IPv6) and opens the socket. Logs once
  // when the address is not a loopback one (OSC has neither authentication nor encryption).
  // `allow_many_receivers` (--allow-remote): broadcast, multicast and unspecified addresses
  // are allowed. `what` names the output in messages. Empty, or what is wrong and what to do.
  [[nodiscard]] std::string open(const std::string& host, const std::string& port, const std::string& what,
                                 bool allow_many_receivers = false);
  // Sends one datagram without blocking. False with `out_error` set when it was not sent.
  [[nodiscard]] bool send(const void* data, std::size_t size, std::string& out_error);
  // Sends one serialised bundle (empty: liblo could not serialise it) and counts it when sent.
  [[nodiscard]] bool send_bundle(const std::vector<std::uint8_t>& bytes, std::string& out_error);
  // Bundles sent by send_bundle(); any thread may read it.
  [[nodiscard]] std::uint64_t bundles_sent() const { return bundles_sent_.load(std::memory_order_relaxed); }
  void close();
  // The resolved address, "127.0.0.1:9000" or "[::1]:9000" (empty before open()).
  [[nodiscard]] const std::string& address() const { return address_; }
  [[nodiscard]] bool loopback() const { return loopback_; }

 private:
  int fd_ = -1;
  std::string address_;
  bool loopback_ = false;
  std::atomic<std::uint64_t> bundles_sent_{0};
};

class OscBundle : NonCopyable {
 public:
  OscBundle();
  ~OscBundle();

  // Adds a message at `path` with `float_count` float arguments (all 0). Returns its index.
  int add_floats(const std::string& path, int float_count);
  // Adds a message built by the caller (any types; liblo's lo_message_add_*). The bundle
  // takes ownership. Returns its index.
  int add_message(const std::string& path, lo_message message);
  // The arguments of message `index`, pointing into the message: write numbers here
  // (set_float for a float) before serialise().
  [[nodiscard]] lo_arg** args(int index) const { return argv_[static_cast<std::size_t>(index)]; }
  // By bytes: liblo packs the arguments at 4-byte steps, so an lo_arg (a union with 8-byte
  // members) may be misaligned and ->f on it is undefined behaviour (UBSan, make sanitize).
  void set_float(int index, int arg, float value) { std::memcpy(args(index)[arg], &value, sizeof value); }
  // Serialises the bundle (time tag "immediately") into the owned buffer. Empty on failure.
  [[nodiscard]] const std::vector<std::uint8_t>& serialise();

 private:
  lo_bundle bundle_ = nullptr;
  std::vector<lo_message> messages_;
  std::deque<std::string> paths_;  // stable addresses, in case liblo keeps the path pointer
  std::vector<lo_arg**> argv_;
  std::vector<std::uint8_t> bytes_;
};

}  // namespace bodyd::daemon
