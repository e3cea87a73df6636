#include "bodyd/motion/tracker_log.h"

#include "bodyd/motion/printable.h"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <iterator>
#include <limits>

namespace bodyd {

Quat unit_rotation(const Quat& q) {
  constexpr double kTolerance = 8.0 * std::numeric_limits<double>::epsilon();
  return std::abs(q.squaredNorm() - 1.0) <= kTolerance ? q : q.normalized();
}

namespace {

constexpr std::string_view kVersionPrefix = "# bodyd-tracker-log ";
constexpr int kFieldCount = 10;
constexpr std::array<std::string_view, kFieldCount> kFieldNames{"t_ns", "role", "valid", "px", "py",
                                                                 "pz",   "qx",   "qy",    "qz", "qw"};

bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

std::string_view trim(std::string_view s) {
  while (!s.empty() && is_blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_blank(s.back())) s.remove_suffix(1);
  return s;
}

// Quoted input in messages: at most 40 characters, control and non-ASCII bytes escaped, so
// garbage input cannot flood or corrupt a terminal.
std::string quote(std::string_view s) { return quote_printable(s, 40); }

bool is_key_char(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' ||
         c == '.';
}

// Parses a number field; returns an empty string on success, otherwise what is wrong.
std::string parse_double(std::string_view field, double& out) {
  if (field.empty()) return "is empty";
  const char* first = field.data();
  const char* last = field.data() + field.size();
  if (*first == '+') ++first;
  auto [ptr, ec] = std::from_chars(first, last, out);
  if (ec == std::errc::result_out_of_range) return fmt::format("{} is out of range for a double", quote(field));
  if (ec != std::errc() || ptr != last) return fmt::format("{} is not a number", quote(field));
  if (!std::isfinite(out)) return fmt::format("{} is not finite", quote(field));
  return {};
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Parser

TrackerLogParser::TrackerLogParser(std::string source_name) : source_(std::move(source_name)) {}

void TrackerLogParser::fail(const std::string& what) const {
  throw TrackerLogError(fmt::format("{}:{}", source_, line_ < 1 ? 1 : line_), what);
}

std::optional<TrackerSample> TrackerLogParser::feed_line(std::string_view raw) {
  ++line_;
  // Trailing blanks (and the '\r' of CRLF files) are not part of any field.
  std::string_view line = raw;
  while (!line.empty() && is_blank(line.back())) line.remove_suffix(1);

  switch (state_) {
    case State::Version:
      // A UTF-8 byte order mark (EF BB BF, what some Windows editors put first) is skipped, as
      // the config reader does; a UTF-16 one means the file is not UTF-8 at all.
      if (line_ == 1 && line.starts_with("\xEF\xBB\xBF")) line.remove_prefix(3);
      if (line_ == 1 && (line.starts_with("\xFF\xFE") || line.starts_with("\xFE\xFF")))
        fail("the file is UTF-16 text (it starts with a UTF-16 byte order mark): save it as UTF-8 "
             "(docs/tracker-log.md)");
      if (line == kTrackerLogVersionLine) {
        state_ = State::Preamble;
        return std::nullopt;
      }
      if (line.starts_with(kVersionPrefix))
        fail(fmt::format("unsupported tracker log version {} (this reader reads v1)",
                         quote(line.substr(kVersionPrefix.size()))));
      fail(fmt::format("missing version line: the first line must be '{}', found {}", kTrackerLogVersionLine,
                       quote(line)));
    case State::Preamble: {
      if (trim(line).empty()) return std::nullopt;
      if (line.front() == '#') {
        std::string_view body = trim(line.substr(1));
        const size_t colon = body.find(':');
        bool is_pair = colon != std::string_view::npos && colon > 0;
        for (size_t i = 0; is_pair && i < colon; ++i) is_pair = is_key_char(body[i]);
        if (is_pair) {
          metadata_.emplace_back(std::string(body.substr(0, colon)), std::string(trim(body.substr(colon + 1))));
          if (metadata_.back().first == kTrackerLogPoseFrameKey) {
            const std::optional<PoseFrame> f = pose_frame_from_name(metadata_.back().second);
            if (!f)
              fail(fmt::format("{}: must be 'joint' or 'device', found {} (docs/tracker-log.md)", kTrackerLogPoseFrameKey,
                               quote(metadata_.back().second)));
            frame_ = *f;
          }
        } else
          metadata_.emplace_back(std::string(), std::string(body));
        return std::nullopt;
      }
      if (line != kTrackerLogHeader)
        fail(fmt::format("wrong column header: expected '{}', found {}", kTrackerLogHeader, quote(line)));
      state_ = State::Samples;
      return std::nullopt;
    }
    case State::Samples: {
      if (trim(line).empty() || line.front() == '#') return std::nullopt;
      TrackerSample s = parse_sample(line);
      s.frame = frame_;
      auto& last = last_t_ns_[static_cast<size_t>(s.role)];
      if (last && s.t_ns <= *last)
        fail(fmt::format("t_ns {} is not after the previous {} sample's t_ns {}: time must increase within "
                         "each role",
                         s.t_ns, role_name(s.role), *last));
      last = s.t_ns;
      return s;
    }
  }
  fail("internal error: bad parser state");
}

TrackerSample TrackerLogParser::parse_sample(std::string_view line) const {
  std::array<std::string_view, kFieldCount> f;
  int count = 0;
  size_t start = 0;
  for (;;) {
    const size_t comma = line.find(',', start);
    const std::string_view field = line.substr(start, comma == std::string_view::npos ? line.npos : comma - start);
    if (count < kFieldCount) f[static_cast<size_t>(count)] = trim(field);
    ++count;
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  if (count != kFieldCount)
    fail(fmt::format("expected {} comma-separated fields ({}), found {}", kFieldCount, kTrackerLogHeader, count));

  TrackerSample s;
  {
    const std::string_view t = f[0];
    const char* first = t.data();
    const char* last = t.data() + t.size();
    auto [ptr, ec] = std::from_chars(first, last, s.t_ns);
    if (t.empty()) fail("t_ns is empty");
    if (ec == std::errc::result_out_of_range) fail(fmt::format("t_ns {} is out of range for int64", quote(t)));
    if (ec != std::errc() || ptr != last)
      fail(fmt::format("t_ns {} is not an integer number of nanoseconds", quote(t)));
    if (!limits::time_plausible(s.t_ns))
      fail(fmt::format("t_ns {} is outside the plausible range +-{} ns (about 146 years; docs/tracker-log.md "
                       "\"Limits\"): is the column in nanoseconds from a sane epoch? Rebase the log's times",
                       s.t_ns, limits::kMaxAbsTimeNs));
  }
  const std::optional<Role> role = role_from_name(f[1]);
  if (!role) fail(fmt::format("unknown role {} (expected one of {})", quote(f[1]), role_names_list()));
  s.role = *role;
  if (f[2] == "1")
    s.valid = true;
  else if (f[2] == "0")
    s.valid = false;
  else
    fail(fmt::format("valid {} must be 0 or 1", quote(f[2])));

  std::array<double, 7> v{};
  // A valid sample with px, py, pz all empty has a rotation only (an IMU tracker).
  if (s.valid && f[3].empty() && f[4].empty() && f[5].empty()) s.has_position = false;
  for (size_t i = 0; i < v.size(); ++i) {
    const std::string_view field = f[3 + i];
    // Invalid samples carry no pose: the writer leaves these fields empty; numbers
    // (e.g. zeros from other tools) are accepted and ignored.
    if ((!s.valid || (i < 3 && !s.has_position)) && field.empty()) continue;
    if (std::string err = parse_double(field, v[i]); !err.empty())
      fail(fmt::format("{} {}", kFieldNames[3 + i], err));
  }
  if (!s.valid) return s;
  for (size_t i = 0; i < 3 && s.has_position; ++i)
    if (!limits::position_plausible(v[i]))
      fail(fmt::format("{} {} m is outside the plausible range +-{} m (docs/tracker-log.md \"Limits\"): is the "
                       "position in metres? Fix or drop the line, or mark the sample invalid (valid 0)",
                       kFieldNames[3 + i], v[i], limits::kMaxAbsPositionM));
  s.position_m = Vec3(v[0], v[1], v[2]);
  const Quat q(v[6], v[3], v[4], v[5]);  // Eigen's constructor takes (w, x, y, z)
  const double norm = q.norm();
  if (!(std::abs(norm - 1.0) <= kTrackerLogQuatNormTolerance))
    fail(fmt::format("quaternion (qx,qy,qz,qw) = ({}, {}, {}, {}) has length {:.6g}, not 1 (tolerance {}); "
                     "are the columns in the order qx,qy,qz,qw?",
                     v[3], v[4], v[5], v[6], norm, kTrackerLogQuatNormTolerance));
  s.rotation = unit_rotation(q);  // idempotent: the daemon's conditioning ends with it too
  return s;
}

void TrackerLogParser::finish() const {
  if (state_ == State::Version)
    fail(fmt::format("empty input: expected the version line '{}'", kTrackerLogVersionLine));
  if (state_ == State::Preamble)
    fail(fmt::format("input ends before the column header line '{}'", kTrackerLogHeader));
}

// ---------------------------------------------------------------------------------------------
// Readers

TrackerLog parse_tracker_log(std::string_view text, const std::string& source_name) {
  TrackerLogParser parser(source_name);
  TrackerLog log;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    if (auto s = parser.feed_line(text.substr(pos, end - pos))) log.samples.push_back(*s);
    pos = end + 1;
  }
  parser.finish();
  log.metadata = parser.metadata();
  return log;
}

TrackerLog read_tracker_log(const std::filesystem::path& path) {
  TrackerLogReader reader(path);
  TrackerLog log;
  while (auto s = reader.next()) log.samples.push_back(*s);
  log.metadata = reader.metadata();
  return log;
}

TrackerLogReader::TrackerLogReader(const std::filesystem::path& path)
    : in_(path, std::ios::binary), parser_(path.string()) {
  if (!in_) throw TrackerLogError(path.string(), "cannot open file", "check the path and that the file is readable");
  while (!parser_.header_seen()) {
    if (!read_line(line_)) {
      parser_.finish();  // throws: no version or no header
      break;
    }
    (void)parser_.feed_line(line_);  // no sample can come before the header
  }
}

bool TrackerLogReader::read_line(std::string& out_line) {
  if (!std::getline(in_, out_line)) {
    if (in_.bad()) throw TrackerLogError(parser_.source_name(), "read error");
    return false;
  }
  return true;
}

std::optional<TrackerSample> TrackerLogReader::next() {
  while (!done_) {
    if (!read_line(line_)) {
      done_ = true;
      parser_.finish();
      break;
    }
    if (auto s = parser_.feed_line(line_)) return s;
  }
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------------
// Writer

std::string tracker_log_preamble(const TrackerLogMetadata& metadata) {
  std::string out(kTrackerLogVersionLine);
  out += '\n';
  for (const auto& [key, value] : metadata) {
    if (value.find_first_of("\r\n") != std::string::npos)
      throw TrackerLogError(
          "", fmt::format("cannot write tracker log: metadata {} value contains a line break", quote(key)));
    if (key.empty()) {  // a free-form comment line, as the reader keeps it
      out += fmt::format("# {}\n", value);
      continue;
    }
    for (char c : key)
      if (!is_key_char(c))
        throw TrackerLogError(
            "", fmt::format("cannot write tracker log: metadata key {} may hold only letters, digits, '_', '-', '.'",
                            quote(key)));
    out += fmt::format("# {}: {}\n", key, value);
  }
  out += kTrackerLogHeader;
  out += '\n';
  return out;
}

void append_tracker_sample(std::string& out, const TrackerSample& s) {
  if (static_cast<int>(s.role) >= kRoleCount)
    throw TrackerLogError("", fmt::format("cannot write tracker log: sample at t_ns {} has no valid role", s.t_ns));
  auto it = std::back_inserter(out);
  if (!limits::time_plausible(s.t_ns))
    throw TrackerLogError("", fmt::format("cannot write tracker log: {} sample t_ns {} is outside the plausible range "
                                          "+-{} ns",
                                          role_name(s.role), s.t_ns, limits::kMaxAbsTimeNs));
  if (!s.valid) {
    fmt::format_to(it, "{},{},0,,,,,,,\n", s.t_ns, role_name(s.role));
    return;
  }
  const Vec3& p = s.position_m;
  const Quat& q = s.rotation;
  if (s.has_position && (!limits::position_plausible(p.x()) || !limits::position_plausible(p.y()) ||
                         !limits::position_plausible(p.z())))
    throw TrackerLogError("", fmt::format("cannot write tracker log: {} sample at t_ns {} has position ({}, {}, {}) m, "
                                          "outside the plausible range +-{} m per coordinate",
                                          role_name(s.role), s.t_ns, p.x(), p.y(), p.z(), limits::kMaxAbsPositionM));
  if (!q.coeffs().allFinite() || !(std::abs(q.norm() - 1.0) <= kTrackerLogQuatNormTolerance))
    throw TrackerLogError(
        "", fmt::format("cannot write tracker log: {} sample at t_ns {} has a non-finite or non-unit quaternion",
                        role_name(s.role), s.t_ns));
  if (!s.has_position) {
    fmt::format_to(it, "{},{},1,,,,{},{},{},{}\n", s.t_ns, role_name(s.role), q.x(), q.y(), q.z(), q.w());
    return;
  }
  fmt::format_to(it, "{},{},1,{},{},{},{},{},{},{}\n", s.t_ns, role_name(s.role), p.x(), p.y(), p.z(), q.x(), q.y(),
                 q.z(), q.w());
}

std::string format_tracker_log(const std::vector<TrackerSample>& samples, const TrackerLogMetadata& metadata) {
  std::string out = tracker_log_preamble(metadata);
  out.reserve(out.size() + samples.size() * 110);
  // What the reader will say the samples are: they must all be that (a round trip keeps frames).
  PoseFrame declared = PoseFrame::Joint;
  for (const auto& [key, value] : metadata)
    if (key == kTrackerLogPoseFrameKey) {
      const std::optional<PoseFrame> f = pose_frame_from_name(value);
      if (!f)
        throw TrackerLogError("",
                              fmt::format("cannot write tracker log: pose_frame '{}' is not joint or device", value));
      declared = *f;
    }
  std::array<std::optional<std::int64_t>, kRoleCount> last{};
  for (const TrackerSample& s : samples) {
    if (s.valid && s.frame != declared)
      throw TrackerLogError(
          "",
          fmt::format("cannot write tracker log: {} sample at t_ns {} is a {} pose but the "
                      "metadata says pose_frame {}",
                      role_name(s.role), s.t_ns, pose_frame_name(s.frame), pose_frame_name(declared)),
          fmt::format("add the metadata line '{}: {}'", kTrackerLogPoseFrameKey, pose_frame_name(s.frame)));
    append_tracker_sample(out, s);  // checks the role before it indexes `last`
    auto& l = last[static_cast<size_t>(s.role)];
    if (l && s.t_ns <= *l)
      throw TrackerLogError("", fmt::format("cannot write tracker log: {} sample t_ns {} is not after the previous {}",
                                            role_name(s.role), s.t_ns, *l));
    l = s.t_ns;
  }
  return out;
}

void write_tracker_log(const std::filesystem::path& path, const std::vector<TrackerSample>& samples,
                       const TrackerLogMetadata& metadata) {
  const std::string text = format_tracker_log(samples, metadata);
  std::ofstream out(path, std::ios::binary);
  if (!out)
    throw TrackerLogError(path.string(), "cannot open for writing", "check that the folder exists and is writable");
  out << text;
  out.flush();
  if (!out) throw TrackerLogError(path.string(), "write failed", "check the free disk space");
}

}  // namespace bodyd
