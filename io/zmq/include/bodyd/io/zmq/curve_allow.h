// CURVE client allow-list (--curve-allow DIR, docs/daemon.md "Security", docs/control.md).
//
// With only a server key, CURVE encrypts and any client that knows the server's public key
// gets in. With an allow-list, bodyd also checks *who* connects: a ZAP handler (ZeroMQ
// Authentication Protocol, RFC 27, https://rfc.zeromq.org/spec/27/) answers the libzmq
// handshakes of both sockets and accepts only the client public keys in DIR, one key per file
// named NAME.public (what `bodyd --gen-keys DIR --client NAME` writes). A refused client's
// handshake fails: it receives nothing and its requests go unanswered.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <thread>
#include <vector>

namespace bodyd::daemon {

// The allowed client keys of DIR: every regular file NAME.public holding one Z85 key (the
// format of read_curve_key_file). Other files are skipped and listed in `out_skipped` (a
// *.secret file there is a mistake worth a warning). Empty on success; otherwise which file
// is wrong and why (a NAME.public that is a symbolic link is refused), or that DIR holds no
// key at all (nobody could connect).
[[nodiscard]] std::string load_curve_allow_dir(const std::filesystem::path& dir, std::set<std::string>& out_keys,
                                               std::vector<std::string>& out_skipped);

// The ZAP handler: a REP socket on inproc://zeromq.zap.01 of the daemon's ZeroMQ context and
// its thread. start() before the CURVE sockets bind; stop() before the context terminates.
class ZapAllowList {
 public:
  ZapAllowList() = default;
  ZapAllowList(const ZapAllowList&) = delete;
  ZapAllowList& operator=(const ZapAllowList&) = delete;
  ~ZapAllowList() { stop(); }

  // Binds the handler in `zmq_context` and starts answering. `keys`: Z85 public keys.
  [[nodiscard]] std::string start(void* zmq_context, std::set<std::string> keys, std::string dir_for_messages);
  void stop();

  [[nodiscard]] std::uint64_t accepted() const { return accepted_.load(); }
  [[nodiscard]] std::uint64_t refused() const { return refused_.load(); }
  [[nodiscard]] std::size_t key_count() const { return keys_.size(); }

 private:
  void loop();

  void* socket_ = nullptr;
  std::set<std::string> keys_;
  std::string dir_;
  static constexpr std::size_t kLoggedKeys = 8;  // refused keys each logged once; then at a limited rate
  std::set<std::string> refused_logged_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> accepted_{0}, refused_{0};
};

}  // namespace bodyd::daemon
