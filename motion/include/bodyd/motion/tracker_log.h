// Tracker logs: recorded tracker samples as versioned CSV text (spec: docs/tracker-log.md).
//
//   # bodyd-tracker-log v1
//   # source: walk.bvh                      <- optional metadata lines "# key: value"
//   t_ns,role,valid,px,py,pz,qx,qy,qz,qw
//   0,head,1,0.01,1.62,0.03,0,0,0,1
//   0,left_hand,0,,,,,,,                   <- invalid: the seven pose fields are empty
//
// Decoding is pure (TrackerLogParser takes lines, does no I/O); the file and string
// readers and TrackerLogReader (incremental, for replay) are built on it. Every
// malformed input throws TrackerLogError whose message is "source:line: what"; no
// input crashes the reader. The writer produces exactly what the reader accepts, and
// a written log reads back to the same samples (positions bit-exact; quaternions are
// renormalised on read, so they agree to a few ulp).
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/motion/limits.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace bodyd {

class TrackerLogError : public UserError {
 public:
  using UserError::UserError;
};

inline constexpr std::string_view kTrackerLogVersionLine = "# bodyd-tracker-log v1";
inline constexpr std::string_view kTrackerLogHeader = "t_ns,role,valid,px,py,pz,qx,qy,qz,qw";
// The metadata line "# pose_frame: device" says the samples are device poses (docs/tracker-log.md;
// TrackerSample::frame); "joint", or no such line, keeps them joint poses (every older log).
inline constexpr std::string_view kTrackerLogPoseFrameKey = "pose_frame";
// A valid sample's quaternion must have | |q| - 1 | <= this; it is then renormalised
// (unit_rotation).
inline constexpr double kTrackerLogQuatNormTolerance = limits::kQuatNormTolerance;

// `q` made unit length, idempotently: q itself when its squared norm is already 1 to within
// 8 ulp (q.normalized() gives one to within 3), else q.normalized(). So unit_rotation(
// unit_rotation(q)) == unit_rotation(q) bit for bit, which q.normalized() is not (about a third
// of random quaternions change again). The reader below and the daemon's sample conditioning
// both end with it, so a recorded session replays to bit-identical reconstructor inputs.
[[nodiscard]] Quat unit_rotation(const Quat& q);
// Plausible ranges (docs/tracker-log.md "Limits"): each position coordinate within
// +-limits::kMaxAbsPositionM metres, |t_ns| <= limits::kMaxAbsTimeNs. The reader rejects
// a line outside them, the writer refuses to write one.

// "# key: value" lines between the version line and the header, in file order.
// A '#' line without "key:" is kept with an empty key and the text as value.
using TrackerLogMetadata = std::vector<std::pair<std::string, std::string>>;

struct TrackerLog {
  TrackerLogMetadata metadata;
  std::vector<TrackerSample> samples;  // in file order
};

// Line-by-line decoder. Feed every line of the file in order (without the '\n'; a
// trailing '\r' is accepted); call finish() at the end of the input. Not thread-safe;
// one parser per log.
class TrackerLogParser {
 public:
  explicit TrackerLogParser(std::string source_name);

  // Decodes the next line. Returns the sample if the line held one, nullopt for the
  // version, metadata, header, comment and blank lines. Throws TrackerLogError.
  [[nodiscard]] std::optional<TrackerSample> feed_line(std::string_view line);
  // Throws TrackerLogError if the input ended before the version or header line.
  void finish() const;

  [[nodiscard]] int line_number() const { return line_; }  // of the last line fed (1-based)
  [[nodiscard]] bool header_seen() const { return state_ == State::Samples; }
  [[nodiscard]] const TrackerLogMetadata& metadata() const { return metadata_; }
  [[nodiscard]] const std::string& source_name() const { return source_; }

 private:
  enum class State { Version, Preamble, Samples };
  [[noreturn]] void fail(const std::string& what) const;
  TrackerSample parse_sample(std::string_view line) const;
  PoseFrame frame_ = PoseFrame::Joint;  // from the pose_frame metadata line

  std::string source_;
  State state_ = State::Version;
  int line_ = 0;
  TrackerLogMetadata metadata_;
  std::array<std::optional<std::int64_t>, kRoleCount> last_t_ns_{};  // per role, for ordering
};

// Whole-log readers. `source_name` names the text in error messages.
[[nodiscard]] TrackerLog parse_tracker_log(std::string_view text, const std::string& source_name);
[[nodiscard]] TrackerLog read_tracker_log(const std::filesystem::path& path);

// Incremental reader over a file (for replay): reads one line at a time.
class TrackerLogReader {
 public:
  // Opens the file and reads up to and including the header line (so metadata() is
  // available at once). Throws TrackerLogError.
  explicit TrackerLogReader(const std::filesystem::path& path);
  // The next sample, or nullopt at the end of the file. Throws TrackerLogError.
  [[nodiscard]] std::optional<TrackerSample> next();
  [[nodiscard]] const TrackerLogMetadata& metadata() const { return parser_.metadata(); }
  [[nodiscard]] int line_number() const { return parser_.line_number(); }

 private:
  bool read_line(std::string& out_line);
  std::ifstream in_;
  TrackerLogParser parser_;
  std::string line_;
  bool done_ = false;
};

// Writer. Metadata keys must be non-empty without ':' or line breaks, values without
// line breaks. A valid sample must have a finite position and a finite quaternion within
// the norm tolerance; format/write_tracker_log also check that time increases within each
// role. Violations throw TrackerLogError, so whatever is written reads back. Samples are
// written in the given order; invalid samples get empty pose fields. Numbers are written in the shortest form that
// reads back to the same double.
[[nodiscard]] std::string tracker_log_preamble(const TrackerLogMetadata& metadata = {});  // version..header
void append_tracker_sample(std::string& out, const TrackerSample& sample);                // one line + '\n'
[[nodiscard]] std::string format_tracker_log(const std::vector<TrackerSample>& samples,
                                             const TrackerLogMetadata& metadata = {});
void write_tracker_log(const std::filesystem::path& path, const std::vector<TrackerSample>& samples,
                       const TrackerLogMetadata& metadata = {});

}  // namespace bodyd
