#include "bodyd/io/zmq/zmq_publisher.h"


#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <zmq.h>

#include <sys/socket.h>

#include <algorithm>
#include <utility>
#include <array>
#include <atomic>
#include <cerrno>
#include <cstring>

namespace bodyd::daemon {
namespace {
constexpr std::int64_t kSkeletonPeriodNs = 1'000'000'000;  // docs/protocol.md: once per second
// Subscribers at once: a quarter of the free descriptors, within these (connection_cap).
constexpr std::size_t kMinSubscribers = 4, kMaxSubscribers = 64;
constexpr int kBacklog = 8;  // connections the kernel queues before bodyd accepts them
}

ZmqPublisher::ZmqPublisher(std::string endpoint, std::string what, const OutputEnv& config)
    : endpoint_(std::move(endpoint)),
      what_(std::move(what)),
      curve_secret_file_(config.curve_secret_key_file),
      curve_allow_dir_(config.curve_allow_dir),
      allow_remote_(config.allow_remote),
      send_hwm_(config.send_hwm) {}

std::string ZmqPublisher::open() {
  if (std::string e = socket_.open(ZMQ_XPUB, "XPUB"); !e.empty()) return e;
  void* pub = socket_.get();
  const int verboser = 1, linger_ms = 500;
  zmq_setsockopt(pub, ZMQ_SNDHWM, &send_hwm_, sizeof(send_hwm_));
  // Every subscribe and unsubscribe reaches us: subscriber counting, --wait-for-subscriber,
  // and the skeleton sent to each new subscriber.
  zmq_setsockopt(pub, ZMQ_XPUB_VERBOSER, &verboser, sizeof(verboser));
  zmq_setsockopt(pub, ZMQ_LINGER, &linger_ms, sizeof(linger_ms));
  if (std::string e = set_curve_server(pub, curve_secret_file_, curve_public_); !e.empty()) return e;
  if (!curve_allow_dir_.empty() && !curve_public_.empty())
    if (std::string e = socket_.allow_only_keys_in(curve_allow_dir_); !e.empty()) return e;
  // Subscribers are capped, so idle ones cannot take every descriptor (out of descriptors, libzmq
  // 4.3 aborts the process in an ipc:// listener's accept()); a short listen queue bounds how many
  // wait beyond the cap.
  const int backlog = kBacklog;
  zmq_setsockopt(pub, ZMQ_BACKLOG, &backlog, sizeof backlog);
  if (std::string e = guard_.start(socket_.context(), pub, what_, connection_cap(kMinSubscribers, kMaxSubscribers));
      !e.empty())
    return e;
  std::string e = bind_socket(pub, endpoint_, what_, allow_remote_, !curve_public_.empty(), bound_);
  guard_.set_bound(bound_);
  return e;
}

bool ZmqPublisher::send(const OutputFrame& frame, std::string& out_error) {
  // A pose names its skeleton by id: a subscriber gets a new skeleton before the first pose
  // that names it (the same socket keeps the order).
  if (skeleton_pending_) publish_skeleton(frame.arrival_ns);
  const auto topic = protocol::kPoseTopic;
  // Never blocks: PUB drops for a subscriber whose queue (send_hwm) is full.
  if (zmq_send(socket_.get(), topic.data(), topic.size(), ZMQ_SNDMORE | ZMQ_DONTWAIT) >= 0 &&
      zmq_send(socket_.get(), frame.message_bytes.data(), frame.message_bytes.size(), ZMQ_DONTWAIT) >= 0)
    return true;
  out_error = "zmq_send: " + zmq_error_text();
  return false;
}

void ZmqPublisher::poll(std::int64_t now_ns) {
  read_subscriptions(now_ns);
  if (skeleton_pending_ || now_ns - last_skeleton_ns_ >= kSkeletonPeriodNs) publish_skeleton(now_ns);
}

void ZmqPublisher::set_skeleton(const Skeleton&, const std::vector<std::uint8_t>& bytes) {
  skeleton_bytes_ = bytes;
  skeleton_pending_ = true;
}

void ZmqPublisher::publish_skeleton(std::int64_t now_ns) {
  if (skeleton_bytes_.empty() || !socket_.get()) return;
  const auto topic = protocol::kSkeletonTopic;
  if (zmq_send(socket_.get(), topic.data(), topic.size(), ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
      zmq_send(socket_.get(), skeleton_bytes_.data(), skeleton_bytes_.size(), ZMQ_DONTWAIT) < 0)
    skeleton_failed_.fetch_add(1, std::memory_order_relaxed);
  else
    skeleton_pending_ = false;
  last_skeleton_ns_ = now_ns;
}

bool ZmqPublisher::read_subscriptions(std::int64_t now_ns) {
  bool any = false;
  std::array<char, 256> buffer{};
  for (;;) {
    const int n = zmq_recv(socket_.get(), buffer.data(), buffer.size(), ZMQ_DONTWAIT);
    if (n < 1) break;
    any = true;
    const std::string_view topic(buffer.data() + 1, std::min<std::size_t>(static_cast<std::size_t>(n), buffer.size()) - 1);
    if (buffer[0] == 1) {
      subscriptions_.fetch_add(1, std::memory_order_relaxed);
      spdlog::debug("new subscription \"{}\"", topic);
      // Whoever subscribes to the skeleton topic gets it at once (otherwise within a second).
      if (protocol::kSkeletonTopic.substr(0, topic.size()) == topic) publish_skeleton(now_ns);
    } else if (buffer[0] == 0 && subscriptions_.load(std::memory_order_relaxed) > 0) {
      subscriptions_.fetch_sub(1, std::memory_order_relaxed);
    }
  }
  return any;
}

bool ZmqPublisher::wait_for_subscription(int timeout_ms, std::int64_t now_ns) {
  zmq_pollitem_t item{socket_.get(), 0, ZMQ_POLLIN, 0};
  return zmq_poll(&item, 1, timeout_ms) > 0 && read_subscriptions(now_ns);
}

nlohmann::json ZmqPublisher::status() const {
  return {{"subscriptions", subscriptions()}, {"skeleton_sends_failed", skeleton_sends_failed()},
          {"curve", !curve_public_.empty()}, {"max_subscribers", guard_.max_connections()},
          {"subscribers_refused", guard_.refused()}};
}

std::unique_ptr<ZmqPublisher> make_pub_output(std::string endpoint, const OutputEnv& env) {
  return std::make_unique<ZmqPublisher>(std::move(endpoint), "--pub", env);
}

std::unique_ptr<Output> make_zmq_output(const OutputSpec& spec, const OutputEnv& env, std::string& error) {
  if (std::string e = check_options(spec, {}); !e.empty()) {
    error = e;
    return nullptr;
  }
  if (spec.target.empty()) {
    error = "--output " + spec.text + ": expected zmq:ENDPOINT, e.g. zmq:tcp://127.0.0.1:5571";
    return nullptr;
  }
  return std::make_unique<ZmqPublisher>(spec.target, "--output zmq:", env);
}

}  // namespace bodyd::daemon
