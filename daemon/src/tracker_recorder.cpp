#include "bodyd/daemon/tracker_recorder.h"

#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace bodyd::daemon {

namespace {

constexpr std::size_t kFlushBytes = 64 * 1024;

const char* file_kind(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISLNK(mode)) return "a symbolic link";
  return "not a regular file";
}

std::string not_regular(const std::string& where, const char* kind) {
  return where + ": is " + kind + ", not a regular file: a recording goes to a new regular file (name one)";
}

}  // namespace

std::string TrackerRecorder::open(const std::string& path, const TrackerLogMetadata& metadata, bool overwrite) {
  close();
  path_ = path;
  error_.clear();
  error_what_.clear();
  last_skip_reason_.clear();
  const std::string where = "--record-trackers " + path;
  std::string preamble;
  try {
    preamble = tracker_log_preamble(metadata);
  } catch (const TrackerLogError& e) {
    return where + ": " + e.what();
  }
  const std::string symlink_refused =
      where + ": is a symbolic link: bodyd does not follow links for a recording (name the file itself)";
  const std::string exists_refused = where +
                                     ": exists: bodyd does not replace a file with a recording (name a new file, or "
                                     "give --overwrite, config \"overwrite\": true, to replace it)";
  // lstat first for the clearer message; open()'s O_EXCL, O_NOFOLLOW and the fstat below are
  // what holds if the path changes in between.
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (S_ISLNK(st.st_mode)) return symlink_refused;
    if (!S_ISREG(st.st_mode)) return not_regular(where, file_kind(st.st_mode));
    if (!overwrite) return exists_refused;
  }
  // O_NONBLOCK: opening a FIFO must not wait for a reader (with none it fails with ENXIO).
  const int flags = O_WRONLY | O_CREAT | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC | (overwrite ? 0 : O_EXCL);
  const int fd = ::open(path.c_str(), flags, 0644);
  if (fd < 0) {
    const int e = errno;
    if (e == EEXIST) return exists_refused;
    if (e == ELOOP) return symlink_refused;
    if (e == ENXIO) return not_regular(where, "a FIFO or a device");
    if (e == EISDIR) return not_regular(where, "a directory");
    return where + ": cannot create the file: " + std::strerror(e);
  }
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return not_regular(where, file_kind(st.st_mode));
  }
  if (overwrite && ::ftruncate(fd, 0) != 0) {
    const int e = errno;
    ::close(fd);
    return where + ": cannot replace the file: " + std::strerror(e);
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  fd_ = fd;
  buffer_ = std::move(preamble);
  buffer_.reserve(kFlushBytes + 256);
  sample_ends_.clear();
  sample_ends_.reserve(1024);
  file_bytes_ = 0;
  last_flush_ns_ = 0;
  seen_.fill(false);
  written_ = skipped_ = lost_ = 0;
  flush();
  if (!error_.empty()) {
    ::close(fd_);
    fd_ = -1;
  }
  return error_;
}

bool TrackerRecorder::record(const TrackerSample& sample) {
  if (fd_ < 0) return false;
  if (!error_.empty()) {
    ++lost_;  // nothing more is written after a write error
    return false;
  }
  const int role = static_cast<int>(sample.role);
  std::string reason;
  if (role < 0 || role >= kRoleCount) reason = "no valid role";
  else if (seen_[role] && sample.t_ns <= last_t_ns_[role])
    reason = "its time is not after the previous " + std::string(role_name(sample.role)) + " sample's";
  if (reason.empty()) {
    const std::size_t before = buffer_.size();
    try {
      append_tracker_sample(buffer_, sample);
    } catch (const TrackerLogError& e) {
      buffer_.resize(before);
      reason = e.what();
    }
  }
  if (!reason.empty()) {
    ++skipped_;
    // Once per kind of problem at warning level; a device repeating it must not flood the log.
    if (reason != last_skip_reason_) spdlog::warn("--record-trackers {}: a sample was not recorded: {}", path_, reason);
    last_skip_reason_ = reason;
    return false;
  }
  seen_[role] = true;
  last_t_ns_[role] = sample.t_ns;
  sample_ends_.push_back(buffer_.size());
  if (buffer_.size() >= kFlushBytes) flush();
  return true;
}

void TrackerRecorder::comment(const std::string& text) {
  if (fd_ < 0 || !error_.empty()) return;
  buffer_ += "# ";
  for (char c : text) buffer_ += (c == '\n' || c == '\r') ? ' ' : c;
  buffer_ += '\n';
}

void TrackerRecorder::poll(std::int64_t now_ns) {
  // An empty buffer restarts the interval: what comes next waits at most kFlushIntervalNs,
  // and the file gets at most two writes a second however the samples come.
  if (buffer_.empty()) last_flush_ns_ = now_ns;
  if (fd_ < 0 || now_ns - last_flush_ns_ < kFlushIntervalNs) return;
  flush();
  last_flush_ns_ = now_ns;
}

void TrackerRecorder::flush() {
  if (fd_ < 0 || buffer_.empty()) return;
  std::size_t done = 0;
  if (error_.empty()) {
    while (done < buffer_.size()) {
      const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
      if (n > 0) {
        done += static_cast<std::size_t>(n);
        continue;
      }
      if (n < 0 && errno == EINTR) continue;
      const int e = n < 0 ? errno : EIO;
      // A partial line at the end would make the file unreadable: cut back to the last whole one.
      std::size_t keep = done;
      while (keep > 0 && buffer_[keep - 1] != '\n') --keep;
      if (keep < done && ::ftruncate(fd_, static_cast<off_t>(file_bytes_ + keep)) == 0) done = keep;
      const auto in_file = static_cast<std::uint64_t>(
          std::upper_bound(sample_ends_.begin(), sample_ends_.end(), done) - sample_ends_.begin());
      error_what_ = std::strerror(e);
      error_ = "--record-trackers " + path_ + ": write failed after " + std::to_string(written_ + in_file) +
               " samples: " + error_what_;
      spdlog::error("{} (nothing more is recorded; the file holds the samples before the error)", error_);
      break;
    }
  }
  const auto in_file = static_cast<std::uint64_t>(
      std::upper_bound(sample_ends_.begin(), sample_ends_.end(), done) - sample_ends_.begin());
  written_ += in_file;
  lost_ += sample_ends_.size() - in_file;
  file_bytes_ += done;
  buffer_.clear();
  sample_ends_.clear();
}

void TrackerRecorder::close() {
  if (fd_ < 0) return;
  flush();
  if (::close(fd_) != 0 && error_.empty()) {
    error_what_ = std::strerror(errno);
    error_ = "--record-trackers " + path_ + ": " + error_what_;
    spdlog::error("{} (the recording may be incomplete)", error_);
  }
  fd_ = -1;
  const std::string skipped = skipped_ ? ", " + std::to_string(skipped_) + " skipped" : std::string();
  if (lost_ == 0 && error_.empty())
    spdlog::info("--record-trackers {}: {} samples recorded{}", path_, written_, skipped);
  else
    spdlog::error("--record-trackers {}: incomplete: {} samples recorded, {} not recorded after the write error{} ({})",
                  path_, written_, lost_, skipped, error_what_);
}

}  // namespace bodyd::daemon
