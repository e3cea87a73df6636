// --record-trackers FILE (config key "record_trackers", docs/daemon.md): every tracker sample
// the reconstruction receives, from every source, written as a tracker log v1
// (docs/tracker-log.md), so a live session replays later with `bodyd --replay FILE --fast` to
// the same poses.
//
// The samples are recorded as the reconstructor sees them: after the per-device offsets and
// the re-centring (`reset`), so a replay needs neither; the header's metadata says what was
// applied (sources, offsets, calibration). Their rotations are recorded before the final
// normalisation that the log reader also does, and the daemon feeds the reconstructor that
// normalised rotation, so replayed poses are bit-identical.
//
// Written by the reconstruction thread: a line per sample appended to a buffer that goes to
// the file every 64 KiB (about every 3 s at 3 x 90 Hz) and at close. Not thread-safe.
#pragma once

#include "bodyd/motion/tracker.h"
#include "bodyd/motion/tracker_log.h"

#include <array>
#include <cstdint>
#include <cstdio>
#include <string>

namespace bodyd::daemon {

class TrackerRecorder {
 public:
  TrackerRecorder() = default;
  TrackerRecorder(const TrackerRecorder&) = delete;
  TrackerRecorder& operator=(const TrackerRecorder&) = delete;
  ~TrackerRecorder() { close(); }

  // Creates (truncates) the file and writes the version line, `metadata` and the header.
  // Empty on success; otherwise the path and what is wrong.
  [[nodiscard]] std::string open(const std::string& path, const TrackerLogMetadata& metadata);
  [[nodiscard]] bool is_open() const { return file_ != nullptr; }

  // Appends one sample. A sample the log could not hold (its time not after the previous one
  // of its role, a value out of the log's limits) is skipped and counted, never written: the
  // file stays readable. Returns false when skipped.
  bool record(const TrackerSample& sample);
  // A comment line ("# text") at this point of the stream, e.g. a calibration change.
  void comment(const std::string& text);

  // Writes what is buffered and closes the file.
  void close();

  [[nodiscard]] std::uint64_t written() const { return written_; }
  [[nodiscard]] std::uint64_t skipped() const { return skipped_; }
  [[nodiscard]] const std::string& error() const { return error_; }  // first write error, if any
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  void flush();

  std::FILE* file_ = nullptr;
  std::string path_, buffer_, error_, last_skip_reason_;
  std::array<std::int64_t, kRoleCount> last_t_ns_{};
  std::array<bool, kRoleCount> seen_{};
  std::uint64_t written_ = 0, skipped_ = 0;
};

}  // namespace bodyd::daemon
