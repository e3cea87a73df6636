#include "bodyd/io/osc/network_source.h"

#include "network_protocol.h"

#include "bodyd/base/log_rate.h"
#include "bodyd/base/loopback.h"
#include "bodyd/base/spec_options.h"
#include "bodyd/io/open_source.h"

#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

namespace bodyd::drivers {

std::uint64_t NetworkStats::rejected_total() const {
  std::uint64_t n = 0;
  for (std::uint64_t r : rejected) n += r;
  return n;
}

namespace {

bool parse_port(std::string_view text, int& out) {
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(text.data(), end, out);
  return !text.empty() && ec == std::errc() && ptr == end && out >= 0 && out <= 65535;
}

// Resolves an IPv4 host ("127.0.0.1", "localhost", "0.0.0.0", a name). Empty on success.
std::string resolve_ipv4(const std::string& host, in_addr& out) {
  if (inet_pton(AF_INET, host.c_str(), &out) == 1) return {};
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  if (const int e = getaddrinfo(host.c_str(), nullptr, &hints, &found); e != 0 || !found)
    return "cannot resolve \"" + host + "\" to an IPv4 address (" + gai_strerror(e) + ")";
  out = reinterpret_cast<const sockaddr_in*>(found->ai_addr)->sin_addr;
  freeaddrinfo(found);
  return {};
}

std::string address_text(const sockaddr_in& a) {
  char text[INET_ADDRSTRLEN] = "?";
  inet_ntop(AF_INET, &a.sin_addr, text, sizeof text);
  return std::string(text) + ":" + std::to_string(ntohs(a.sin_port));
}

// The socket, the receiver thread and the counters of every network input; what a datagram
// means is the protocol's decoder's (network_protocol.h).
class UdpSource final : public NetworkSource, private detail::DatagramResult {
 public:
  UdpSource(NetworkSourceOptions options, int fd, int port, std::unique_ptr<detail::NetworkDecoder> decoder)
      : options_(std::move(options)), fd_(fd), port_(port), decoder_(std::move(decoder)) {
    buffer_.resize(65536);
  }
  ~UdpSource() override {
    UdpSource::stop();
    decoder_.reset();
    if (fd_ >= 0) close(fd_);
  }

  // After the bind (vrchat: starts OSCQuery). Empty, or what went wrong.
  std::string open_decoder() { return decoder_->open(options_, port_); }

  const std::string& name() const override { return options_.name; }

  std::string start(SampleSink& sink, std::uint16_t source_index) override {
    if (thread_.joinable()) return options_.name + ": already started";
    sink_ = &sink;
    source_index_ = source_index;
    stop_.store(false);
    set_error("listening on " + options_.host + ":" + std::to_string(port_) + "; nothing received yet");
    thread_ = std::thread([this] { run(); });
    return {};
  }

  void stop() override {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }

  SourceStatus status() const override {
    SourceStatus s;
    s.name = options_.name;
    const std::int64_t last = last_datagram_ns_.load(std::memory_order_relaxed);
    s.connected = thread_.joinable() && last != 0 && monotonic_ns() - last < 2'000'000'000;
    const NetworkStats st = stats();
    s.samples = st.samples;
    s.rejected = st.rejected_total();
    for (int i = 1; i < kInputRejectCount; ++i)
      s.rejected_by_reason[std::string(input_reject_name(static_cast<InputReject>(i)))] = st.rejected[i];
    s.counters["datagrams"] = st.datagrams;
    s.counters["ignored"] = st.ignored;
    decoder_->add_counters(st, s);
    std::lock_guard lock(mutex_);
    s.rate_hz = s.connected ? rate_.rate_hz() : 0.0;
    s.last_error = last_error_;
    return s;
  }

  NetworkStats stats() const override {
    NetworkStats st;
    st.datagrams = datagrams_.load(std::memory_order_relaxed);
    st.samples = samples_.load(std::memory_order_relaxed);
    st.ignored = ignored_.load(std::memory_order_relaxed);
    st.unassigned = unassigned_.load(std::memory_order_relaxed);
    for (int i = 0; i < kInputRejectCount; ++i) st.rejected[i] = rejected_[i].load(std::memory_order_relaxed);
    return st;
  }

  int bound_port() const override { return port_; }
  int oscquery_port() const override { return decoder_->oscquery_port(); }
  std::string mdns_state() const override { return decoder_->mdns_state(); }

 private:
  void run() {
    sockaddr_in from{};
    bool said_error = false;
    while (!stop_.load(std::memory_order_relaxed)) {
      socklen_t from_len = sizeof from;
      // MSG_TRUNC: the return value is the datagram's real length even when the buffer is shorter.
      const ssize_t n = recvfrom(fd_, buffer_.data(), buffer_.size(), MSG_TRUNC,
                                 reinterpret_cast<sockaddr*>(&from), &from_len);
      if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) continue;  // the read timeout: check stop
        if (!said_error) spdlog::error("{}: receive failed: {}", options_.name, std::strerror(errno));
        said_error = true;
        set_error(std::string("receive failed: ") + std::strerror(errno));
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
        continue;
      }
      const std::int64_t arrival_ns = monotonic_ns();  // stamped before any decoding
      // The first datagram makes start()'s "nothing received yet" untrue (issue 20).
      if (datagrams_.fetch_add(1, std::memory_order_relaxed) == 0) set_error({});
      last_datagram_ns_.store(arrival_ns, std::memory_order_relaxed);
      const auto size = static_cast<std::size_t>(n);
      if (size > buffer_.size()) {
        reject(InputReject::Oversized, "datagram of " + std::to_string(size) + " bytes", from);
        continue;
      }
      handle(buffer_.data(), size, arrival_ns, from);
    }
  }

  void handle(const std::uint8_t* data, std::size_t size, std::int64_t arrival_ns, const sockaddr_in& from) {
    pending_.clear();
    from_ = &from;
    decoder_->decode(data, size, arrival_ns, *this);
    // Hands before the head: the daemon reconstructs when a head sample arrives, and should
    // see the hands of the same packet.
    std::stable_partition(pending_.begin(), pending_.end(), [](const Pending& p) { return p.sample.role != Role::Head; });
    for (const Pending& p : pending_) push(p, arrival_ns);
  }

  // detail::DatagramResult: what the decoder found in the datagram from *from_.
  void use(const TrackerSample& sample, std::int64_t device_t_ns, bool has_device_time) override {
    pending_.push_back({sample, device_t_ns, has_device_time});
  }
  void ignore() override { ignored_.fetch_add(1, std::memory_order_relaxed); }
  void unassigned() override { unassigned_.fetch_add(1, std::memory_order_relaxed); }
  void reject(InputReject why, const std::string& detail) override { reject(why, detail, *from_); }

  struct Pending {
    TrackerSample sample;
    std::int64_t device_t_ns = 0;
    bool has_device_time = false;
  };

  void push(const Pending& p, std::int64_t arrival_ns) {
    SourceSample s;
    s.sample = p.sample;
    s.arrival_ns = arrival_ns;
    s.device_t_ns = p.device_t_ns;
    s.has_device_time = p.has_device_time;
    s.source_index = source_index_;
    sink_->push(s);
    samples_.fetch_add(1, std::memory_order_relaxed);
    std::lock_guard lock(mutex_);
    rate_.count(arrival_ns);
  }

  // Counted, then logged when the count is a power of two (1, 2, 4, ...): no log flood.
  void reject(InputReject why, const std::string& detail, const sockaddr_in& from) {
    rejected_[static_cast<int>(why)].fetch_add(1, std::memory_order_relaxed);
    const std::uint64_t n = total_rejected_.fetch_add(1, std::memory_order_relaxed) + 1;
    const std::string text =
        "rejected a packet from " + address_text(from) + ": " + std::string(input_reject_name(why)) + ": " + detail;
    if (log_occurrence(n)) spdlog::warn("{}: {} ({} rejected so far)", options_.name, text, n);
    set_error(text);
  }

  void set_error(std::string text) {
    std::lock_guard lock(mutex_);
    last_error_ = std::move(text);
  }

  NetworkSourceOptions options_;
  int fd_ = -1;
  int port_ = 0;
  std::unique_ptr<detail::NetworkDecoder> decoder_;
  SampleSink* sink_ = nullptr;
  std::uint16_t source_index_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  // Receiver thread only.
  std::vector<std::uint8_t> buffer_;
  std::vector<Pending> pending_;
  const sockaddr_in* from_ = nullptr;  // the datagram's sender, while the decoder runs
  // Counters: written by the receiver thread, read by any.
  std::atomic<std::uint64_t> datagrams_{0}, samples_{0}, ignored_{0}, unassigned_{0}, total_rejected_{0};
  std::array<std::atomic<std::uint64_t>, kInputRejectCount> rejected_{};
  std::atomic<std::int64_t> last_datagram_ns_{0};
  mutable std::mutex mutex_;  // guards the members below
  std::string last_error_;
  RateMeter rate_;
};

}  // namespace

std::optional<NetworkSourceOptions> parse_network_spec(NetworkKind kind, std::string_view spec,
                                                       std::string_view argument, std::string& error) {
  NetworkSourceOptions o;
  o.name = std::string(spec);
  const std::string where = "source \"" + std::string(spec) + "\"";
  const detail::NetworkProtocol* protocol = detail::network_protocol(kind);
  if (!protocol) {
    error = where + ": no network protocol \"" + std::string(kind.scheme) + "\" (io/osc/network_protocols.cpp)";
    return std::nullopt;
  }
  o.kind = NetworkKind{protocol->scheme};  // the row's own text, which outlives the options
  const auto [address, query] = split_spec_query(argument);
  if (address.empty()) {
    if (protocol->default_port == 0) {
      error = where + ": missing the port, e.g. " + std::string(kind.scheme) + ":127.0.0.1:9100";
      return std::nullopt;
    }
    o.port = protocol->default_port;
  } else {
    std::string_view port = address;
    if (const auto colon = address.rfind(':'); colon != std::string_view::npos) {
      o.host = std::string(address.substr(0, colon));
      port = address.substr(colon + 1);
      if (o.host.empty()) {
        error = where + ": empty host before ':' (write " + std::string(kind.scheme) + ":PORT or HOST:PORT)";
        return std::nullopt;
      }
    }
    if (!parse_port(port, o.port)) {
      error = where + ": \"" + std::string(port) + "\" is not a UDP port (0..65535)";
      return std::nullopt;
    }
  }
  // The options by the one spec rule (bodyd/base/spec_options.h); which keys, the protocol's row.
  std::vector<SpecOption> options;
  if (std::string e = parse_spec_options(query, options); !e.empty()) {
    error = where + ": " + e + " (" + std::string(protocol->options_help) + ")";
    return std::nullopt;
  }
  for (const SpecOption& option : options) {
    if (!protocol->option(option.key, option.value, o)) {
      error = where + ": unknown option \"" + option.key + "=" + option.value + "\" (" +
              std::string(protocol->options_help) + ")";
      return std::nullopt;
    }
  }
  return o;
}

std::unique_ptr<NetworkSource> open_network_source(const NetworkSourceOptions& options, std::string& error) {
  const std::string where = options.name + ": ";
  const detail::NetworkProtocol* protocol = detail::network_protocol(options.kind);
  if (!protocol) {
    error = where + "no network protocol \"" + std::string(options.kind.scheme) + "\" (io/osc/network_protocols.cpp)";
    return nullptr;
  }
  in_addr addr{};
  if (std::string e = resolve_ipv4(options.host, addr); !e.empty()) {
    error = where + e;
    return nullptr;
  }
  if (!is_loopback(addr) && !options.allow_remote) {
    error = where + "binding to " + options.host +
            " would let any machine that reaches it move the avatar: OSC and UDP have no authentication. "
            "Bind to 127.0.0.1, or give --allow-remote (config \"allow_remote\": true) on a network you trust";
    return nullptr;
  }
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    error = where + "cannot create a UDP socket: " + std::strerror(errno);
    return nullptr;
  }
  timeval timeout{0, 100'000};  // 100 ms: the receiver notices stop() within it
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  const int buffer_bytes = 1 << 20;  // room for bursts while the thread is descheduled
  setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &buffer_bytes, sizeof buffer_bytes);
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(static_cast<std::uint16_t>(options.port));
  sa.sin_addr = addr;
  if (bind(fd, reinterpret_cast<const sockaddr*>(&sa), sizeof sa) != 0) {
    const int e = errno;
    close(fd);
    error = where + "cannot listen on " + options.host + ":" + std::to_string(options.port) + ": " +
            std::strerror(e) +
            (e == EADDRINUSE ? " (another program, or another bodyd, is using the port: pick another port, and tell "
                               "the sender)"
                             : "");
    return nullptr;
  }
  socklen_t len = sizeof sa;
  getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
  auto source = std::make_unique<UdpSource>(options, fd, ntohs(sa.sin_port), protocol->decoder(options));
  if (std::string e = source->open_decoder(); !e.empty()) {
    error = e;
    return nullptr;
  }
  return source;
}

// The registry's factory and check (sources.cpp): vrchat:, vmc: and udp:, the protocol named
// by the spec's scheme.
std::unique_ptr<TrackerSource> open_network_spec(const SourceSpec& spec, const SourceOptions& options,
                                                 std::string& error) {
  std::optional<NetworkSourceOptions> network =
      parse_network_spec(NetworkKind{spec.scheme->scheme}, spec.text, spec.argument, error);
  if (!network) return nullptr;
  network->allow_remote = options.allow_remote;
  return open_network_source(*network, error);
}

std::string check_network_spec(const SourceSpec& spec) {
  std::string error;
  if (!parse_network_spec(NetworkKind{spec.scheme->scheme}, spec.text, spec.argument, error)) return error;
  return {};
}

}  // namespace bodyd::drivers
