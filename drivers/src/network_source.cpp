#include "bodyd/drivers/network_source.h"

#include "oscquery.h"
#include "vmc_roles.h"

#include "bodyd/motion/printable.h"

#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <bit>
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

std::string_view kind_prefix(NetworkKind kind) {
  switch (kind) {
    case NetworkKind::Vrchat: return "vrchat:";
    case NetworkKind::Vmc: return "vmc:";
    case NetworkKind::Udp: return "udp:";
  }
  return "";
}

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

bool is_loopback(in_addr a) { return (ntohl(a.s_addr) >> 24) == 127; }

std::string address_text(const sockaddr_in& a) {
  char text[INET_ADDRSTRLEN] = "?";
  inet_ntop(AF_INET, &a.sin_addr, text, sizeof text);
  return std::string(text) + ":" + std::to_string(ntohs(a.sin_port));
}

class UdpSource final : public NetworkSource {
 public:
  UdpSource(NetworkSourceOptions options, int fd, int port)
      : options_(std::move(options)), fd_(fd), port_(port), vmc_roles_(options_.name, options_.vmc_roles) {
    buffer_.resize(65536);
  }
  ~UdpSource() override {
    UdpSource::stop();
    oscquery_.reset();
    if (fd_ >= 0) close(fd_);
  }

  std::string start_oscquery() {
    std::string error;
    oscquery_ = detail::OscQueryService::start(options_.oscquery_name, options_.host, port_, error);
    if (!oscquery_) return options_.name + ": " + error;
    spdlog::info("{}: OSCQuery on http://{}:{}/ (VRChat finds bodyd through it when mDNS works)", options_.name,
                 options_.host == "0.0.0.0" ? "127.0.0.1" : options_.host, oscquery_->http_port());
    return {};
  }

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
    if (options_.kind == NetworkKind::Vmc) s.counters["unassigned"] = st.unassigned;
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
  int oscquery_port() const override { return oscquery_ ? oscquery_->http_port() : 0; }
  std::string mdns_state() const override { return oscquery_ ? oscquery_->mdns_state() : "off"; }

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
    std::string detail;
    if (options_.kind == NetworkKind::Udp) {
      TrackerSample s;
      std::int64_t sender_t_ns = 0;
      InputReject why = InputReject::None;
      switch (decode_tracker_line(data, size, s, sender_t_ns, why, detail)) {
        case MessageUse::Use:
          s.t_ns = arrival_ns;
          pending_.push_back({s, sender_t_ns, true});
          break;
        case MessageUse::Ignore: ignored_.fetch_add(1, std::memory_order_relaxed); break;
        case MessageUse::Reject: reject(why, detail, from); break;
      }
    } else {
      if (InputReject why = decode_osc_packet(data, size, messages_, detail, options_.limits); why != InputReject::None) {
        reject(why, detail, from);
        return;
      }
      for (const OscMessage& m : messages_) handle_message(m, arrival_ns, from);
    }
    // Hands before the head: the daemon reconstructs when a head sample arrives, and should
    // see the hands of the same packet.
    std::stable_partition(pending_.begin(), pending_.end(), [](const Pending& p) { return p.sample.role != Role::Head; });
    for (const Pending& p : pending_) push(p, arrival_ns);
  }

  void handle_message(const OscMessage& m, std::int64_t arrival_ns, const sockaddr_in& from) {
    InputReject why = InputReject::None;
    MessageUse use = MessageUse::Ignore;
    if (options_.kind == NetworkKind::Vrchat) {
      VrchatPose pose;
      use = decode_vrchat_message(m, pose, why);
      if (use == MessageUse::Use) pending_.push_back({sample_from_vrchat(pose, arrival_ns), 0, false});
    } else {
      VmcPose pose;
      use = decode_vmc_message(m, pose, why);
      if (use == MessageUse::Use) {
        const std::optional<Role> role = vmc_roles_.role_of(pose, arrival_ns);
        if (!role) {
          unassigned_.fetch_add(1, std::memory_order_relaxed);
          return;
        }
        TrackerSample s;
        s.t_ns = arrival_ns;
        s.role = *role;
        s.valid = true;
        s.position_m = pose.position_m;
        s.rotation = pose.rotation;
        pending_.push_back({s, 0, false});
      }
    }
    if (use == MessageUse::Ignore) ignored_.fetch_add(1, std::memory_order_relaxed);
    if (use == MessageUse::Reject) reject(why, quote_printable(m.address, 64) + " with type tags ," + printable(m.type_tags), from);
  }

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
    if (std::has_single_bit(n)) spdlog::warn("{}: {} ({} rejected so far)", options_.name, text, n);
    set_error(text);
  }

  void set_error(std::string text) {
    std::lock_guard lock(mutex_);
    last_error_ = std::move(text);
  }

  NetworkSourceOptions options_;
  int fd_ = -1;
  int port_ = 0;
  std::unique_ptr<detail::OscQueryService> oscquery_;
  SampleSink* sink_ = nullptr;
  std::uint16_t source_index_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  // Receiver thread only.
  std::vector<std::uint8_t> buffer_;
  std::vector<OscMessage> messages_;
  std::vector<Pending> pending_;
  detail::VmcRoles vmc_roles_;
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
  o.kind = kind;
  o.name = std::string(spec);
  const std::string where = "source \"" + std::string(spec) + "\"";
  std::string_view address = argument, query;
  if (const auto q = argument.find('?'); q != std::string_view::npos) {
    address = argument.substr(0, q);
    query = argument.substr(q + 1);
  }
  if (address.empty()) {
    if (kind == NetworkKind::Udp) {
      error = where + ": missing the port, e.g. udp:127.0.0.1:9100";
      return std::nullopt;
    }
    o.port = kind == NetworkKind::Vrchat ? 9001 : 39539;
  } else {
    std::string_view port = address;
    if (const auto colon = address.rfind(':'); colon != std::string_view::npos) {
      o.host = std::string(address.substr(0, colon));
      port = address.substr(colon + 1);
      if (o.host.empty()) {
        error = where + ": empty host before ':' (write " + std::string(kind_prefix(kind)) + "PORT or HOST:PORT)";
        return std::nullopt;
      }
    }
    if (!parse_port(port, o.port)) {
      error = where + ": \"" + std::string(port) + "\" is not a UDP port (0..65535)";
      return std::nullopt;
    }
  }
  while (!query.empty()) {
    const auto amp = query.find('&');
    const std::string_view item = query.substr(0, amp);
    query = amp == std::string_view::npos ? std::string_view() : query.substr(amp + 1);
    const auto eq = item.find('=');
    const std::string key(item.substr(0, eq));
    const std::string value(eq == std::string_view::npos ? std::string_view() : item.substr(eq + 1));
    if (kind == NetworkKind::Vrchat && key == "oscquery" && (value == "on" || value == "off")) {
      o.oscquery = value == "on";
    } else if (kind == NetworkKind::Vrchat && key == "name" && !value.empty()) {
      o.oscquery_name = value;
    } else if (kind == NetworkKind::Vmc && role_from_name(key) && !value.empty()) {
      o.vmc_roles[value] = *role_from_name(key);
    } else {
      error = where + ": unknown option \"" + std::string(item) + "\" (" +
              (kind == NetworkKind::Vrchat ? "vrchat: takes oscquery=on|off and name=NAME"
               : kind == NetworkKind::Vmc  ? "vmc: takes head=SERIAL, left_hand=SERIAL, right_hand=SERIAL"
                                           : "udp: takes no options") +
              ")";
      return std::nullopt;
    }
  }
  return o;
}

std::unique_ptr<NetworkSource> open_network_source(const NetworkSourceOptions& options, std::string& error) {
  const std::string where = options.name + ": ";
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
  auto source = std::make_unique<UdpSource>(options, fd, ntohs(sa.sin_port));
  if (options.kind == NetworkKind::Vrchat && options.oscquery) {
    if (std::string e = source->start_oscquery(); !e.empty()) {
      error = e;
      return nullptr;
    }
  }
  return source;
}

}  // namespace bodyd::drivers
