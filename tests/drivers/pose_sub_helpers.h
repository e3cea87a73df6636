// Reading bodyd's pose stream in the drivers' end-to-end tests (docs/protocol.md).
#pragma once

#include "bodyd/protocol/pose_message.h"

#include <zmq.hpp>

#include <chrono>
#include <cstdint>
#include <optional>
#include <vector>

namespace bodyd::test {

// Waits up to `wait` for the next message on `sub`: the pose when it is a pose message that
// decodes; nullopt after a timeout, for another topic, a message without a payload frame or
// one that does not decode (the callers count only good poses).
inline std::optional<protocol::PoseMessage> poll_pose(zmq::socket_t& sub, std::chrono::milliseconds wait) {
  zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
  if (zmq::poll(&item, 1, wait) == 0) return std::nullopt;
  zmq::message_t topic, payload;
  if (!sub.recv(topic, zmq::recv_flags::dontwait) || !topic.more()) return std::nullopt;
  (void)sub.recv(payload);
  while (payload.more()) (void)sub.recv(payload);
  if (topic.to_string_view() != protocol::kPoseTopic) return std::nullopt;
  protocol::PoseMessage pose;
  const auto* p = static_cast<const std::uint8_t*>(payload.data());
  if (!protocol::decode_pose(std::vector<std::uint8_t>(p, p + payload.size()), pose).ok()) return std::nullopt;
  return pose;
}

}  // namespace bodyd::test
