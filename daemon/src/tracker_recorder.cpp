#include "bodyd/daemon/tracker_recorder.h"

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cstring>

namespace bodyd::daemon {

namespace {
constexpr std::size_t kFlushBytes = 64 * 1024;
}

std::string TrackerRecorder::open(const std::string& path, const TrackerLogMetadata& metadata) {
  close();
  path_ = path;
  std::string preamble;
  try {
    preamble = tracker_log_preamble(metadata);
  } catch (const TrackerLogError& e) {
    return "--record-trackers " + path + ": " + e.what();
  }
  file_ = std::fopen(path.c_str(), "wb");
  if (!file_) return "--record-trackers " + path + ": cannot create the file: " + std::strerror(errno);
  buffer_ = std::move(preamble);
  buffer_.reserve(kFlushBytes + 256);
  flush();
  seen_.fill(false);
  written_ = skipped_ = 0;
  return error_;
}

bool TrackerRecorder::record(const TrackerSample& sample) {
  if (!file_) return false;
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
  ++written_;
  if (buffer_.size() >= kFlushBytes) flush();
  return true;
}

void TrackerRecorder::comment(const std::string& text) {
  if (!file_) return;
  buffer_ += "# ";
  for (char c : text) buffer_ += (c == '\n' || c == '\r') ? ' ' : c;
  buffer_ += '\n';
}

void TrackerRecorder::flush() {
  if (!file_ || buffer_.empty()) return;
  if (std::fwrite(buffer_.data(), 1, buffer_.size(), file_) != buffer_.size() && error_.empty()) {
    error_ = "--record-trackers " + path_ + ": write failed: " + std::strerror(errno);
    spdlog::error("{} (the recording is incomplete)", error_);
  }
  buffer_.clear();
}

void TrackerRecorder::close() {
  if (!file_) return;
  flush();
  if (std::fclose(file_) != 0 && error_.empty()) {
    error_ = "--record-trackers " + path_ + ": " + std::strerror(errno);
    spdlog::error("{} (the recording is incomplete)", error_);
  }
  file_ = nullptr;
  spdlog::info("--record-trackers {}: {} samples recorded{}", path_, written_,
               skipped_ ? ", " + std::to_string(skipped_) + " skipped" : std::string());
}

}  // namespace bodyd::daemon
