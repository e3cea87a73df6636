// Pose recordings; format in docs/pose-recording.md.
#include "bodyd/protocol/recording.h"

#include "bytes.h"

#include <fmt/format.h>

#include <cstring>
#include <fstream>

namespace bodyd::protocol {
namespace {

using detail::Reader;

// Record layout: u32 record_size, then record_size bytes: i64 recv_t_ns, u8 topic_length,
// topic, frame.
constexpr std::size_t kRecordPrefixSize = 4;
constexpr std::size_t kRecordFixedSize = 9;  // recv_t_ns + topic_length

Status fail(std::string message) { return Status{std::move(message)}; }

}  // namespace

void append_recording_header(std::int64_t created_unix_ns, std::vector<std::uint8_t>& out) {
  detail::put_bytes(out, kRecordingMagic.data(), kRecordingMagic.size());
  detail::put_u16(out, kRecordingVersion);
  detail::put_u16(out, 0);  // reserved
  detail::put_u32(out, static_cast<std::uint32_t>(kRecordingHeaderSize));
  detail::put_i64(out, created_unix_ns);
}

Status append_recording_frame(std::int64_t recv_t_ns, std::string_view topic, std::span<const std::uint8_t> frame,
                              std::vector<std::uint8_t>& out) {
  if (topic.size() > 255) return fail(fmt::format("recording: topic of {} bytes (maximum 255)", topic.size()));
  const std::size_t size = kRecordFixedSize + topic.size() + frame.size();
  if (size > kMaxRecordSize) {
    return fail(fmt::format("recording: record of {} bytes exceeds the maximum {}", size, kMaxRecordSize));
  }
  detail::put_u32(out, static_cast<std::uint32_t>(size));
  detail::put_i64(out, recv_t_ns);
  detail::put_u8(out, static_cast<std::uint8_t>(topic.size()));
  detail::put_bytes(out, topic.data(), topic.size());
  detail::put_bytes(out, frame.data(), frame.size());
  return {};
}

Status parse_recording(std::span<const std::uint8_t> bytes, Recording& out, bool allow_truncated_tail) {
  out = Recording{};
  Reader r(bytes);
  if (bytes.size() < kRecordingHeaderSize) {
    return fail(fmt::format("{} bytes is shorter than the {}-byte recording header (not a bodyd recording?)",
                            bytes.size(), kRecordingHeaderSize));
  }
  if (std::memcmp(r.at(0), kRecordingMagic.data(), kRecordingMagic.size()) != 0) {
    return fail("wrong magic at byte 0: expected \"BODYDREC\" (not a bodyd pose recording)");
  }
  const std::uint16_t version = r.u16(8);
  if (version != kRecordingVersion) {
    return fail(fmt::format("unsupported recording version {} at byte 8 (this reader reads version {})", version,
                            kRecordingVersion));
  }
  const std::uint32_t header_size = r.u32(12);
  if (header_size < kRecordingHeaderSize || header_size > bytes.size()) {
    return fail(fmt::format("header_size {} at byte 12 is invalid (at least {}, at most the file size {})",
                            header_size, kRecordingHeaderSize, bytes.size()));
  }
  out.created_unix_ns = r.i64(16);
  std::size_t pos = header_size;
  std::size_t index = 0;
  while (pos < bytes.size()) {
    const auto truncated = [&](std::string what) -> Status {
      if (allow_truncated_tail) {
        out.truncated_tail = true;
        return {};
      }
      return fail(fmt::format("record {} at byte {}: {} (file cut short; a recorder killed mid-write?)", index,
                              pos, what));
    };
    if (!r.has(pos, kRecordPrefixSize)) return truncated("truncated record size");
    const std::size_t size = r.u32(pos);
    if (size < kRecordFixedSize || size > kMaxRecordSize) {
      return fail(fmt::format("record {} at byte {}: record_size {} out of range {}..{}", index, pos, size,
                              kRecordFixedSize, kMaxRecordSize));
    }
    const std::size_t body = pos + kRecordPrefixSize;
    if (!r.has(body, size)) {
      return truncated(fmt::format("record_size {} but only {} bytes left", size, bytes.size() - body));
    }
    RecordedFrame f;
    f.recv_t_ns = r.i64(body);
    const std::size_t topic_len = r.u8(body + 8);
    if (kRecordFixedSize + topic_len > size) {
      return fail(fmt::format("record {} at byte {}: topic_length {} does not fit in record_size {}", index, pos,
                              topic_len, size));
    }
    f.topic.assign(reinterpret_cast<const char*>(r.at(body + kRecordFixedSize)), topic_len);
    const std::size_t frame_at = body + kRecordFixedSize + topic_len;
    f.frame.assign(r.at(frame_at), r.at(body + size));
    out.frames.push_back(std::move(f));
    pos = body + size;
    ++index;
  }
  if (r.overrun) return fail("internal error: read past the end (bug in parse_recording)");
  return {};
}

Status load_recording(const std::filesystem::path& path, Recording& out, bool allow_truncated_tail) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(fmt::format("{}: cannot open ({})", path.string(), std::strerror(errno)));
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return fail(fmt::format("{}: read error", path.string()));
  if (Status s = parse_recording(bytes, out, allow_truncated_tail); !s) {
    return fail(fmt::format("{}: {}", path.string(), s.error));
  }
  return {};
}

Status load_pose_recording(const std::filesystem::path& path, PoseRecording& out, bool allow_truncated_tail) {
  out = PoseRecording{};
  Recording rec;
  if (Status s = load_recording(path, rec, allow_truncated_tail); !s) return s;
  out.created_unix_ns = rec.created_unix_ns;
  out.truncated_tail = rec.truncated_tail;
  for (std::size_t i = 0; i < rec.frames.size(); ++i) {
    const RecordedFrame& f = rec.frames[i];
    if (f.topic == kPoseTopic) {
      PoseMessage pose;
      if (Status s = decode_pose(f.frame, pose); !s) {
        return fail(fmt::format("{}: record {}: {}", path.string(), i, s.error));
      }
      out.poses.push_back(std::move(pose));
      out.pose_recv_t_ns.push_back(f.recv_t_ns);
    } else if (f.topic == kSkeletonTopic) {
      SkeletonMessage skeleton;
      if (Status s = decode_skeleton(f.frame, skeleton); !s) {
        return fail(fmt::format("{}: record {}: {}", path.string(), i, s.error));
      }
      if (find_skeleton(out, skeleton.skeleton_id) == nullptr) out.skeletons.push_back(std::move(skeleton));
    }
  }
  return {};
}

const SkeletonMessage* find_skeleton(const PoseRecording& recording, std::uint32_t skeleton_id) {
  for (const SkeletonMessage& s : recording.skeletons) {
    if (s.skeleton_id == skeleton_id) return &s;
  }
  return nullptr;
}

}  // namespace bodyd::protocol
