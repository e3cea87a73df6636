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
// The file (issue 20): an existing one is refused unless `overwrite` (--overwrite); a symbolic
// link is never followed (O_NOFOLLOW) and anything but a regular file (a FIFO, a device, a
// directory) is refused, without blocking: the file is opened with O_NONBLOCK and checked
// with fstat before anything is written.
//
// Written by the reconstruction thread: a line per sample appended to a buffer that goes to
// the file (write(2), so the kernel has it even if bodyd is killed) when poll() finds it at
// least kFlushInterval old, when it reaches 64 KiB and at close. A kill -9 loses at most the
// last half second or so. After a write error nothing more is written; the file is cut back
// to its last complete line (it still reads back) and close() says how many samples really are
// in it. Not thread-safe.
#pragma once

#include "bodyd/motion/tracker.h"
#include "bodyd/motion/tracker_log.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace bodyd::daemon {

class TrackerRecorder {
 public:
  // poll() writes what is buffered once it is this old (monotonic nanoseconds).
  static constexpr std::int64_t kFlushIntervalNs = 500'000'000;

  TrackerRecorder() = default;
  TrackerRecorder(const TrackerRecorder&) = delete;
  TrackerRecorder& operator=(const TrackerRecorder&) = delete;
  ~TrackerRecorder() { close(); }

  // Creates the file (replaces an existing regular file only when `overwrite`) and writes the
  // version line, `metadata` and the header. Empty on success; otherwise the path, what is
  // wrong and what to do.
  [[nodiscard]] std::string open(const std::string& path, const TrackerLogMetadata& metadata, bool overwrite = false);
  [[nodiscard]] bool is_open() const { return fd_ >= 0; }

  // Appends one sample. A sample the log could not hold (its time not after the previous one
  // of its role, a value out of the log's limits) is skipped and counted, never written: the
  // file stays readable. Returns false when skipped (or lost after a write error).
  bool record(const TrackerSample& sample);
  // A comment line ("# text") at this point of the stream, e.g. a calibration change.
  void comment(const std::string& text);
  // Writes the buffer when the last write is at least kFlushIntervalNs before `now_ns`
  // (monotonic). The reconstruction loop calls it every turn.
  void poll(std::int64_t now_ns);

  // Writes what is buffered, closes the file and logs what it holds.
  void close();

  [[nodiscard]] std::uint64_t written() const { return written_; }  // samples in the file (written to it)
  [[nodiscard]] std::uint64_t skipped() const { return skipped_; }  // samples the log cannot hold
  [[nodiscard]] std::uint64_t lost() const { return lost_; }        // samples not written after a write error
  [[nodiscard]] const std::string& error() const { return error_; }  // first write error, if any
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  void flush();

  int fd_ = -1;
  std::string path_, buffer_, error_, error_what_, last_skip_reason_;  // error_what_: strerror of error_
  std::vector<std::size_t> sample_ends_;  // end offset in buffer_ of each sample line buffered
  std::uint64_t file_bytes_ = 0;          // bytes in the file (all complete lines)
  std::int64_t last_flush_ns_ = 0;
  std::array<std::int64_t, kRoleCount> last_t_ns_{};
  std::array<bool, kRoleCount> seen_{};
  std::uint64_t written_ = 0, skipped_ = 0, lost_ = 0;
};

}  // namespace bodyd::daemon
