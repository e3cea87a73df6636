// bodyd-record: save bodyd's pose stream to a file (docs/pose-recording.md).
//
//   bodyd-record --endpoint E --out FILE [--count N] [--duration-s S] [--timeout-s S]
//
// Records every pose and skeleton message as received, with the receive time. Frames that do
// not decode are skipped (and counted), so a recording always loads. Stops after N poses,
// after S seconds, or on SIGINT/SIGTERM, and closes the file cleanly in every case.
#include "bodyd/base/clock.h"
#include "bodyd/protocol/recording.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <zmq.hpp>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop = true; }

}  // namespace

int main(int argc, char** argv) {
  namespace protocol = bodyd::protocol;
  CLI::App app{"Record bodyd's pose stream to a file (docs/pose-recording.md)."};
  std::string endpoint{protocol::kDefaultPoseEndpoint};
  std::string out_path;
  std::uint64_t count = 0;
  double duration_s = 0.0;
  double timeout_s = 0.0;
  app.add_option("--endpoint,-e", endpoint, "pose stream (PUB) endpoint to connect to")->capture_default_str();
  app.add_option("--out,-o", out_path, "recording file to write (replaced if it exists)")->required();
  app.add_option("--count,-n", count, "stop after N poses (0: no limit)");
  app.add_option("--duration-s", duration_s, "stop after this many seconds (0: no limit)")->check(CLI::NonNegativeNumber);
  app.add_option("--timeout-s", timeout_s, "stop with status 2 when no pose arrives for this long (0: wait forever)")
      ->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);

  zmq::context_t context{1};
  zmq::socket_t sub{context, zmq::socket_type::sub};
  try {
    sub.set(zmq::sockopt::linger, 0);
    sub.set(zmq::sockopt::rcvhwm, 10000);
    sub.set(zmq::sockopt::subscribe, protocol::kPoseTopic);
    sub.set(zmq::sockopt::subscribe, protocol::kSkeletonTopic);
    sub.connect(endpoint);
  } catch (const zmq::error_t& e) {
    fmt::print(stderr, "bodyd-record: endpoint \"{}\": {} (expected e.g. ipc:///tmp/bodyd/pose or "
                       "tcp://127.0.0.1:5555)\n", endpoint, e.what());
    return 1;
  }
  std::FILE* file = std::fopen(out_path.c_str(), "wb");
  if (file == nullptr) {
    fmt::print(stderr, "bodyd-record: cannot create {}: {}\n", out_path, std::strerror(errno));
    return 1;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  std::vector<std::uint8_t> buffer;
  const auto created = std::chrono::duration_cast<std::chrono::nanoseconds>(
      std::chrono::system_clock::now().time_since_epoch()).count();
  protocol::append_recording_header(created, buffer);
  bool write_failed = false;
  const auto flush = [&] {
    if (!buffer.empty() && std::fwrite(buffer.data(), 1, buffer.size(), file) != buffer.size()) write_failed = true;
    buffer.clear();
    if (std::fflush(file) != 0) write_failed = true;
  };
  flush();

  const std::int64_t start_ns = bodyd::monotonic_ns();
  std::int64_t last_pose_ns = start_ns;
  std::int64_t last_flush_ns = start_ns;
  std::uint64_t poses = 0, skeletons = 0, skipped = 0, dropped = 0;
  std::optional<std::uint64_t> last_seq;
  zmq::message_t topic, frame;
  protocol::PoseMessage pose;
  protocol::SkeletonMessage skeleton;
  int status = 0;
  while (!g_stop && !write_failed && (count == 0 || poses < count)) {
    const std::int64_t now_ns = bodyd::monotonic_ns();
    if (duration_s > 0 && static_cast<double>(now_ns - start_ns) >= duration_s * 1e9) break;
    if (timeout_s > 0 && static_cast<double>(now_ns - last_pose_ns) > timeout_s * 1e9) {
      fmt::print(stderr, "bodyd-record: no pose from {} for {} s (is bodyd running and publishing there?)\n",
                 endpoint, timeout_s);
      status = 2;
      break;
    }
    if (now_ns - last_flush_ns > 1'000'000'000) {  // a killed recorder loses at most a second
      flush();
      last_flush_ns = now_ns;
    }
    int frames = 0;
    try {
      sub.set(zmq::sockopt::rcvtimeo, 100);
      if (!sub.recv(topic, zmq::recv_flags::none)) continue;
      frames = 1;
      if (sub.get(zmq::sockopt::rcvmore) && sub.recv(frame, zmq::recv_flags::dontwait)) ++frames;
      while (sub.get(zmq::sockopt::rcvmore)) {
        zmq::message_t extra;
        if (!sub.recv(extra, zmq::recv_flags::dontwait)) break;
        ++frames;
      }
    } catch (const zmq::error_t& e) {
      if (e.num() == EINTR) continue;
      fmt::print(stderr, "bodyd-record: receiving from {}: {}\n", endpoint, e.what());
      status = 1;
      break;
    }
    const std::int64_t recv_ns = bodyd::monotonic_ns();
    if (frames != 2) {
      ++skipped;
      continue;
    }
    const std::string_view t(static_cast<const char*>(topic.data()), topic.size());
    const auto bytes = protocol::as_bytes(frame.data(), frame.size());
    protocol::Status decoded;
    if (t == protocol::kPoseTopic) decoded = protocol::decode_pose(bytes, pose);
    else if (t == protocol::kSkeletonTopic) decoded = protocol::decode_skeleton(bytes, skeleton);
    else continue;  // a later protocol's topic
    if (!decoded) {
      if (skipped++ == 0) fmt::print(stderr, "bodyd-record: skipping undecodable {} message: {}\n", t, decoded.error);
      continue;
    }
    if (protocol::Status s = protocol::append_recording_frame(recv_ns, t, bytes, buffer); !s) {
      fmt::print(stderr, "bodyd-record: {}\n", s.error);
      ++skipped;
      continue;
    }
    if (t == protocol::kPoseTopic) {
      ++poses;
      last_pose_ns = recv_ns;
      if (last_seq && pose.seq > *last_seq) dropped += pose.seq - *last_seq - 1;
      last_seq = pose.seq;
    } else {
      ++skeletons;
    }
  }
  flush();
  if (std::fclose(file) != 0) write_failed = true;
  if (write_failed) {
    fmt::print(stderr, "bodyd-record: writing {} failed: {} (disk full?)\n", out_path, std::strerror(errno));
    return 1;
  }
  fmt::print(stderr, "bodyd-record: {} poses, {} skeletons to {} ({} dropped by seq gaps, {} skipped)\n", poses,
             skeletons, out_path, dropped, skipped);
  return status;
}
