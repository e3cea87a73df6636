// Pose recordings (bodyd-record's output): the frames of the pose stream as received, with
// the time each arrived, in a small binary file. Format: docs/pose-recording.md.
//
// Writing is done by pure functions that append to a byte buffer (the caller writes the
// file); reading parses a byte buffer (pure) or loads a file.
#pragma once

#include "bodyd/protocol/pose_message.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::protocol {

inline constexpr std::array<std::uint8_t, 8> kRecordingMagic{'B', 'O', 'D', 'Y', 'D', 'R', 'E', 'C'};
inline constexpr std::uint16_t kRecordingVersion = 1;
inline constexpr std::size_t kRecordingHeaderSize = 24;
// A record larger than this is malformed (a pose frame of kMaxJoints joints is ~3.6 KiB).
inline constexpr std::size_t kMaxRecordSize = 1u << 20;

// One received frame: its topic, its bytes (a pose or skeleton message, undecoded).
struct RecordedFrame {
  std::int64_t recv_t_ns = 0;  // recorder's CLOCK_MONOTONIC when the frame was received
  std::string topic;
  std::vector<std::uint8_t> frame;
};

struct Recording {
  std::int64_t created_unix_ns = 0;  // wall-clock time the recording started (informational)
  std::vector<RecordedFrame> frames;
  bool truncated_tail = false;  // the last record was cut short and dropped (allow_truncated_tail)
};

// Appends the file header to `out`.
void append_recording_header(std::int64_t created_unix_ns, std::vector<std::uint8_t>& out);
// Appends one record to `out`. Topics longer than 255 bytes and frames over kMaxRecordSize
// are refused.
Status append_recording_frame(std::int64_t recv_t_ns, std::string_view topic,
                              std::span<const std::uint8_t> frame, std::vector<std::uint8_t>& out);

// Parses a whole recording. With allow_truncated_tail, a last record cut short (a recorder
// killed mid-write) is dropped and flagged instead of failing.
Status parse_recording(std::span<const std::uint8_t> bytes, Recording& out,
                       bool allow_truncated_tail = false);
// Reads and parses a file; errors name the file and the byte offset.
Status load_recording(const std::filesystem::path& path, Recording& out,
                      bool allow_truncated_tail = false);

// A recording decoded: every pose (in file order) and every skeleton seen.
struct PoseRecording {
  std::int64_t created_unix_ns = 0;
  std::vector<PoseMessage> poses;
  std::vector<std::int64_t> pose_recv_t_ns;  // per pose, when it was received
  std::vector<SkeletonMessage> skeletons;    // each distinct skeleton, in order of first appearance
  bool truncated_tail = false;
};

// Loads a recording and decodes its frames. Frames of unknown topics are skipped; a frame
// that fails to decode is an error naming the file, the record index and the reason.
Status load_pose_recording(const std::filesystem::path& path, PoseRecording& out,
                           bool allow_truncated_tail = false);

// The skeleton a pose follows, from the recording's skeletons, or nullptr.
[[nodiscard]] const SkeletonMessage* find_skeleton(const PoseRecording& recording, std::uint32_t skeleton_id);

}  // namespace bodyd::protocol
