// What the tests that run bodyd and bodyd-ctl as processes share (tests/daemon, tests/tools):
// the programs and a pose subscriber.
#pragma once

#include "test_paths.h"

#include "bodyd/protocol/pose_message.h"

#include <zmq.hpp>

#include <string>

namespace bodyd::test {

inline const std::string kBodyd = (bin_dir() / "bodyd").string();
inline const std::string kCtl = (bin_dir() / "bodyd-ctl").string();

// A SUB socket on `pub` taking every pose message (no receive limit, no linger).
inline zmq::socket_t pose_subscriber(zmq::context_t& ctx, const std::string& pub) {
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, 0);
  sub.set(zmq::sockopt::subscribe, std::string(protocol::kPoseTopic));
  sub.connect(pub);
  return sub;
}

}  // namespace bodyd::test
