// The ZeroMQ pose stream (docs/protocol.md) as an output: an XPUB socket that sends each
// pose and the skeleton: a new skeleton (set_skeleton) before the next pose, which names it,
// then once a second and to every new subscriber of the skeleton topic. The daemon's --pub
// endpoint is one such output (make_pub_output); `--output zmq:ENDPOINT` adds more, which
// behave the same.
#pragma once

#include "bodyd/io/output.h"
#include "bodyd/io/zmq/zmq_util.h"

#include <atomic>
#include <mutex>
#include <string>
#include <vector>

namespace bodyd::daemon {

class ZmqPublisher final : public Output {
 public:
  // `what` names the endpoint's flag in messages ("--pub", "--output zmq:...").
  ZmqPublisher(std::string endpoint, std::string what, const OutputEnv& config);
  ~ZmqPublisher() override { close(); }

  [[nodiscard]] std::string name() const override { return "zmq:" + (bound_.empty() ? endpoint_ : bound_); }
  [[nodiscard]] std::string open() override;
  // Subscribers draw bodyd's body: the user's re-centred space (the pose stream, docs/protocol.md).
  [[nodiscard]] OutputSpace space() const override { return OutputSpace::User; }
  [[nodiscard]] bool send(const OutputFrame& frame, std::string& out_error) override;
  void poll(std::int64_t now_ns) override;
  void set_skeleton(const Skeleton& skeleton, const std::vector<std::uint8_t>& bytes) override;
  [[nodiscard]] nlohmann::json status() const override;
  void close() override {
    guard_.stop();
    socket_.close();
  }

  // Sends the skeleton message now. Counted as a failed send when ZeroMQ refuses it (then it
  // stays pending: the next send() or poll() tries again, before the pose).
  void publish_skeleton(std::int64_t now_ns);
  // Reads subscription messages without blocking; true if one arrived.
  bool read_subscriptions(std::int64_t now_ns);
  // Waits up to timeout_ms for a subscription message; true if one arrived.
  bool wait_for_subscription(int timeout_ms, std::int64_t now_ns);

  [[nodiscard]] const std::string& bound() const { return bound_; }
  [[nodiscard]] const std::string& curve_public_key() const { return curve_public_; }
  [[nodiscard]] std::uint64_t subscriptions() const { return subscriptions_.load(std::memory_order_relaxed); }
  // Skeleton messages ZeroMQ refused to queue.
  [[nodiscard]] std::uint64_t skeleton_sends_failed() const { return skeleton_failed_.load(std::memory_order_relaxed); }

 private:
  std::string endpoint_, what_, curve_secret_file_, curve_allow_dir_, bound_, curve_public_;
  bool allow_remote_ = false;
  int send_hwm_ = 1000;
  ZmqSocket socket_;
  ConnectionGuard guard_;  // after socket_: stopped before the socket closes
  std::vector<std::uint8_t> skeleton_bytes_;  // reconstruction thread only
  std::int64_t last_skeleton_ns_ = 0;
  bool skeleton_pending_ = false;  // set_skeleton() gave one not sent yet (reconstruction thread only)
  std::atomic<std::uint64_t> subscriptions_{0}, skeleton_failed_{0};
};

// The --pub output (config.pub_endpoint; "--pub" in messages).
std::unique_ptr<ZmqPublisher> make_pub_output(std::string endpoint, const OutputEnv& env);
// The "zmq" row of outputs.cpp.
std::unique_ptr<Output> make_zmq_output(const OutputSpec& spec, const OutputEnv& env, std::string& error);

}  // namespace bodyd::daemon
