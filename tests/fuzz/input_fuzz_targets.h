// The input fuzz targets (issue 11): every reader of untrusted bytes besides the device
// decoders (those are in tests/drivers/fuzz_targets.h). Shared by the libFuzzer entry point
// (fuzz_main.cpp, `make fuzz`) and the brief fixed-seed loop in `make test`
// (brief_fuzz_test.cpp). Each target feeds arbitrary bytes to one reader and checks its
// promises: only its own error type escapes (anything else, a crash or UB aborts, and
// libFuzzer keeps the input), and what it accepts is within the limits of
// motion/include/bodyd/motion/limits.h and survives a write/read round trip.
#pragma once

#include "fuzz_check.h"
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/control.h"
#include "bodyd/inference/model_file.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/limits.h"
#include "bodyd/motion/tracker_log.h"
#include "bodyd/protocol/pose_message.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::test {

inline std::string_view as_text(const std::uint8_t* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

// What `read` returns, or nullopt when it throws `Error` (the reader refused the input: nothing
// more to check).
template <class Error, class Read>
auto accepted(Read&& read) -> std::optional<decltype(read())> {
  try {
    return read();
  } catch (const Error&) {
    return std::nullopt;
  }
}

inline bool within_limits(const Vec3& p) {
  return limits::position_plausible(p.x()) && limits::position_plausible(p.y()) && limits::position_plausible(p.z());
}

// Tracker log text (docs/tracker-log.md): parse_tracker_log over the whole input (line by line
// through TrackerLogParser). Accepted samples are within the limits, unit, ordered per role,
// and the writer writes them back to the same samples.
inline void fuzz_tracker_log(const std::uint8_t* data, std::size_t size) {
  const std::optional<TrackerLog> log =
      accepted<TrackerLogError>([&] { return parse_tracker_log(as_text(data, size), "fuzz"); });
  if (!log) return;
  std::array<std::int64_t, kRoleCount> last{};
  std::array<bool, kRoleCount> seen{};
  for (const TrackerSample& s : log->samples) {
    const auto r = static_cast<std::size_t>(s.role);
    fuzz_check(r < kRoleCount, "tracker log: role out of range");
    fuzz_check(limits::time_plausible(s.t_ns), "tracker log: t_ns outside the limits");
    fuzz_check(!seen[r] || s.t_ns > last[r], "tracker log: time not increasing within a role");
    seen[r] = true;
    last[r] = s.t_ns;
    if (!s.valid) continue;
    fuzz_check(within_limits(s.position_m), "tracker log: position outside the limits");
    fuzz_check(std::abs(s.rotation.norm() - 1.0) < 1e-12, "tracker log: rotation not unit length");
  }
  std::string text;
  try {
    text = format_tracker_log(log->samples);
  } catch (const TrackerLogError&) {
    fuzz_check(false, "tracker log: the writer refuses samples the reader accepted");
  }
  const TrackerLog back = parse_tracker_log(text, "fuzz round trip");  // throws (aborts) if not
  fuzz_check(back.samples.size() == log->samples.size(), "tracker log: round trip changed the count");
  for (std::size_t i = 0; i < back.samples.size(); ++i) {
    const TrackerSample& a = log->samples[i];
    const TrackerSample& b = back.samples[i];
    fuzz_check(a.t_ns == b.t_ns && a.role == b.role && a.valid == b.valid, "tracker log: round trip");
    if (a.valid) fuzz_check(a.position_m == b.position_m, "tracker log: round trip changed a position");
  }
}

// BVH text: parse_bvh. An accepted clip has a valid skeleton, lengths within the limits and
// finite forward kinematics in every frame.
inline void fuzz_bvh(const std::uint8_t* data, std::size_t size) {
  const std::optional<Motion> clip = accepted<BvhError>([&] { return parse_bvh(as_text(data, size), "fuzz.bvh"); });
  if (!clip) return;
  const Motion& m = *clip;
  fuzz_check(m.skeleton.validate().empty(), "bvh: accepted an invalid skeleton");
  for (const Vec3& o : m.skeleton.offsets) fuzz_check(within_limits(o), "bvh: OFFSET outside the limits");
  GlobalPose g;
  for (const Pose& pose : m.frames) {
    for (const Vec3& t : pose.local_translations) fuzz_check(within_limits(t), "bvh: position outside limits");
    forward_kinematics(m.skeleton, pose, g);
    for (std::size_t j = 0; j < g.positions.size(); ++j) {
      fuzz_check(g.positions[j].allFinite(), "bvh: forward kinematics not finite");
      fuzz_check(g.rotations[j].coeffs().allFinite(), "bvh: rotation not finite");
    }
  }
}

// Daemon config text (docs/daemon.md), as load_config_file reads it: JSON with comments, then
// apply_config_json and validate_config. Only error strings come back (no exception), and a
// configuration that was accepted prints (config_to_json) to a file that reads back the same.
inline void fuzz_config(const std::uint8_t* data, std::size_t size) {
  const std::string_view text = as_text(data, size);
  nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false, /*ignore_comments=*/true);
  if (j.is_discarded()) return;
  daemon::DaemonConfig config;
  if (!daemon::apply_config_json(j, "fuzz.json", config).empty()) return;
  if (!daemon::validate_config(config).empty()) return;
  const nlohmann::json printed = daemon::config_to_json(config);
  daemon::DaemonConfig again;
  fuzz_check(daemon::apply_config_json(printed, "printed", again).empty(),
                   "config: the printed configuration does not read back");
  fuzz_check(daemon::config_to_json(again) == printed, "config: round trip changed a key");
}

// Control requests (docs/control.md): handle_control_request never throws and always answers
// an object with a boolean "ok".
class FuzzControlTarget final : public daemon::ControlTarget {
 public:
  nlohmann::json status() override { return {{"ok", true}}; }
  nlohmann::json skeleton() override { return {{"ok", true}}; }
  nlohmann::json calibrate_height(double head_height_m) override {
    fuzz_check(std::isfinite(head_height_m), "control: non-finite height reached the target");
    return {{"ok", true}};
  }
  nlohmann::json calibrate_from_head() override { return {{"ok", true}}; }
  nlohmann::json reload_model(const std::optional<std::string>&) override { return {{"ok", true}}; }
  nlohmann::json shutdown() override { return {{"ok", true}}; }
};

inline void fuzz_control(const std::uint8_t* data, std::size_t size) {
  FuzzControlTarget target;
  const nlohmann::json reply = daemon::handle_control_request(as_text(data, size), target);
  fuzz_check(reply.is_object(), "control: reply is not an object");
  fuzz_check(reply.contains("ok") && reply["ok"].is_boolean(), "control: reply has no boolean ok");
  // The reply goes back over the socket as text: it must serialise whatever the request held.
  (void)reply.dump(-1, ' ', false, nlohmann::json::error_handler_t::strict);
}

// Model files (docs/model-file.md): the container decoder and the full model loader throw
// only ModelFileError; a loaded model has what the loader promises.
inline void fuzz_model(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  (void)accepted<inference::ModelFileError>([&] { return inference::parse_tensor_file(bytes, "fuzz.safetensors"); });
  const std::optional<inference::Model> model =
      accepted<inference::ModelFileError>([&] { return inference::parse_model(bytes, "fuzz.safetensors"); });
  if (!model) return;
  fuzz_check(model->norm_std.size() == static_cast<std::size_t>(model->config.dim()), "model: norm_std size");
  for (float s : model->norm_std) fuzz_check(std::isfinite(s) && s > 0.0f, "model: norm_std not positive");
  fuzz_check(model->skeleton.validate().empty(), "model: invalid skeleton");
}

// `bytes` decoded, and that message encoded and decoded again (`back`); nullopt when `bytes`
// do not decode. What decodes must encode, and what it encodes to must decode.
template <class Message>
struct RoundTrip {
  Message decoded, back;
};
template <class Message>
std::optional<RoundTrip<Message>> round_trip(std::span<const std::uint8_t> bytes,
                                             protocol::Status (*decode)(std::span<const std::uint8_t>, Message&),
                                             protocol::Status (*encode)(const Message&, std::vector<std::uint8_t>&),
                                             const char* does_not_encode, const char* does_not_decode_again) {
  RoundTrip<Message> r;
  if (!decode(bytes, r.decoded).ok()) return std::nullopt;
  std::vector<std::uint8_t> again;
  fuzz_check(encode(r.decoded, again).ok(), does_not_encode);
  fuzz_check(decode(again, r.back).ok(), does_not_decode_again);
  return r;
}

// Pose stream frames (docs/protocol.md): decode_pose and decode_skeleton on the same bytes;
// what decodes re-encodes and decodes to the same message.
inline void fuzz_pose_message(const std::uint8_t* data, std::size_t size) {
  using namespace bodyd::protocol;
  const std::span<const std::uint8_t> bytes(data, size);
  if (const auto r = round_trip(bytes, &decode_pose, &encode_pose, "pose: a decoded pose does not encode",
                                "pose: re-encoded pose does not decode")) {
    const PoseMessage& pose = r->decoded;
    const PoseMessage& back = r->back;
    fuzz_check(back.seq == pose.seq && back.t_ns == pose.t_ns && back.publish_t_ns == pose.publish_t_ns &&
                         back.skeleton_id == pose.skeleton_id && back.root_joint == pose.root_joint &&
                         back.joints.size() == pose.joints.size(),
                     "pose: round trip changed a field");
    for (std::size_t i = 0; i < pose.joints.size(); ++i)
      fuzz_check(back.joints[i].position_m == pose.joints[i].position_m, "pose: round trip changed a joint");
  }
  if (const auto r = round_trip(bytes, &decode_skeleton, &encode_skeleton, "skeleton: a decoded skeleton does not encode",
                                "skeleton: re-encoded skeleton does not decode")) {
    const SkeletonMessage& skeleton = r->decoded;
    const SkeletonMessage& back = r->back;
    fuzz_check(back.names == skeleton.names && back.parents == skeleton.parents &&
                         back.offsets_m == skeleton.offsets_m && back.skeleton_id == skeleton.skeleton_id,
                     "skeleton: round trip changed a field");
  }
}

}  // namespace bodyd::test
