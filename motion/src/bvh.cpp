#include "bodyd/motion/bvh.h"

#include "bodyd/motion/limits.h"
#include "bodyd/motion/printable.h"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

namespace bodyd {
namespace {

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

// Splits the text into whitespace-separated tokens, remembering each token's line.
class Tokenizer {
 public:
  Tokenizer(std::string_view text, const std::string& source) : text_(text), source_(source) {}

  // Next token, or an empty view at the end of the text.
  std::string_view next() {
    skip_space();
    const size_t start = pos_;
    token_line_ = line_;
    while (pos_ < text_.size() && !is_space(text_[pos_])) ++pos_;
    return text_.substr(start, pos_ - start);
  }
  std::string_view expect(std::string_view what) {
    std::string_view t = next();
    if (t.empty()) fail(fmt::format("unexpected end of file, expected {}", what));
    return t;
  }
  void expect_literal(std::string_view literal) {
    std::string_view t = next();
    if (t != literal)
      fail(t.empty() ? fmt::format("unexpected end of file, expected '{}'", literal)
                     : fmt::format("expected '{}', found {}", literal, quote_printable(t)));
  }
  double expect_number(std::string_view what) {
    std::string_view t = expect(what);
    return to_number(t, what);
  }
  double to_number(std::string_view t, std::string_view what) {
    double v = 0;
    if (!try_number(t, v)) fail_number(t, what);
    return v;
  }
  // Parses a finite number; false otherwise (the caller builds the message only then).
  static bool try_number(std::string_view t, double& v) {
    const char* first = t.data();
    if (!t.empty() && t.front() == '+') ++first;
    auto [ptr, ec] = std::from_chars(first, t.data() + t.size(), v);
    return ec == std::errc() && ptr == t.data() + t.size() && std::isfinite(v);
  }
  [[noreturn]] void fail_number(std::string_view t, std::string_view what) const {
    double v = 0;
    const char* first = t.data();
    if (!t.empty() && t.front() == '+') ++first;
    auto [ptr, ec] = std::from_chars(first, t.data() + t.size(), v);
    if (ec != std::errc() || ptr != t.data() + t.size()) fail(fmt::format("{}: {} is not a number", what, quote_printable(t)));
    fail(fmt::format("{}: {} is not finite", what, quote_printable(t)));
  }
  // Rest of the current line (after the last token), trimmed; advances to the next line.
  std::string_view rest_of_line() {
    while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\t' || text_[pos_] == '\r')) ++pos_;
    const size_t start = pos_;
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    std::string_view r = text_.substr(start, pos_ - start);
    while (!r.empty() && is_space(r.back())) r.remove_suffix(1);
    return r;
  }
  // Reads the next non-empty line; returns false at the end of the text.
  bool next_line(std::string_view& out_line) {
    while (pos_ < text_.size()) {
      if (text_[pos_] == '\n') {
        ++pos_;
        ++line_;
        continue;
      }
      const size_t start = pos_;
      while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
      std::string_view l = text_.substr(start, pos_ - start);
      token_line_ = line_;
      bool blank = true;
      for (char c : l)
        if (!is_space(c)) blank = false;
      if (!blank) {
        out_line = l;
        return true;
      }
    }
    return false;
  }
  // Moves past the end of the current line (used after "Frame Time:" before frame lines).
  void finish_line() {
    while (pos_ < text_.size() && text_[pos_] != '\n') {
      if (!is_space(text_[pos_])) {
        token_line_ = line_;
        fail(fmt::format("unexpected text {} after the value", quote_printable(rest_of_line())));
      }
      ++pos_;
    }
  }

  [[noreturn]] void fail(const std::string& what) const {
    throw BvhError(fmt::format("{}:{}", source_, token_line_), what);
  }

 private:
  void skip_space() {
    while (pos_ < text_.size() && is_space(text_[pos_])) {
      if (text_[pos_] == '\n') ++line_;
      ++pos_;
    }
  }
  std::string_view text_;
  const std::string& source_;
  size_t pos_ = 0;
  int line_ = 1;
  int token_line_ = 1;
};

bool parse_channel(std::string_view t, Channel& out) {
  static constexpr std::pair<std::string_view, Channel> kNames[] = {
      {"Xposition", Channel::Xposition}, {"Yposition", Channel::Yposition}, {"Zposition", Channel::Zposition},
      {"Xrotation", Channel::Xrotation}, {"Yrotation", Channel::Yrotation}, {"Zrotation", Channel::Zrotation}};
  for (const auto& [name, ch] : kNames) {
    if (t.size() == name.size()) {
      bool eq = true;
      for (size_t i = 0; i < t.size(); ++i)
        if (std::tolower(static_cast<unsigned char>(t[i])) != std::tolower(static_cast<unsigned char>(name[i])))
          eq = false;
      if (eq) {
        out = ch;
        return true;
      }
    }
  }
  return false;
}

std::string_view channel_name(Channel c) {
  switch (c) {
    case Channel::Xposition: return "Xposition";
    case Channel::Yposition: return "Yposition";
    case Channel::Zposition: return "Zposition";
    case Channel::Xrotation: return "Xrotation";
    case Channel::Yrotation: return "Yrotation";
    case Channel::Zrotation: return "Zrotation";
  }
  return "?";
}

bool is_rotation(Channel c) { return c == Channel::Xrotation || c == Channel::Yrotation || c == Channel::Zrotation; }
int axis_of(Channel c) {
  switch (c) {
    case Channel::Xposition: case Channel::Xrotation: return 0;
    case Channel::Yposition: case Channel::Yrotation: return 1;
    default: return 2;
  }
}

constexpr int kMaxJoints = 1024;
// Rotation channels beyond this many degrees are absurd (a thousand turns) and lose precision.
constexpr double kMaxAbsRotationDeg = 1e5;

// A length of the file (OFFSET, position channel) in metres, or a BvhError when it is outside
// the plausible range of a position (limits.h): a finite 1e300 would overflow forward
// kinematics and poison every metric and tracker computed from the clip.
double length_m(const Tokenizer& tok, double value, const BvhReadOptions& opt, std::string_view what) {
  const double m = value * opt.unit_to_m;
  if (!limits::position_plausible(m))
    tok.fail(fmt::format("{} {} is {:.6g} m, outside the plausible range +-{} m (docs/reliability.md \"Limits\"): "
                         "is the file in centimetres? Fix the value or drop the clip",
                         what, value, m, limits::kMaxAbsPositionM));
  return m;
}
constexpr int kMaxFrames = 10'000'000;

void parse_joint(Tokenizer& tok, Motion& m, int parent, std::string name, const BvhReadOptions& opt, int depth) {
  if (depth > 256) tok.fail("hierarchy nested deeper than 256 joints");
  if (m.skeleton.size() >= kMaxJoints) tok.fail(fmt::format("more than {} joints", kMaxJoints));
  for (char c : name)
    if (!is_printable_ascii(static_cast<unsigned char>(c)) && static_cast<unsigned char>(c) < 0x80)
      tok.fail(fmt::format("joint name {} holds a control character; joint names are printable text", quote_printable(name)));
  if (m.skeleton.find(name) >= 0) tok.fail(fmt::format("joint name {} appears twice", quote_printable(name)));
  const int index = m.skeleton.size();
  m.skeleton.names.push_back(std::move(name));
  m.skeleton.parents.push_back(parent);
  m.skeleton.offsets.push_back(Vec3::Zero());
  m.skeleton.end_sites.push_back(std::nullopt);
  m.channels.emplace_back();
  tok.expect_literal("{");
  bool have_offset = false, have_channels = false;
  for (;;) {
    std::string_view t = tok.expect("'OFFSET', 'CHANNELS', 'JOINT', 'End Site' or '}'");
    if (t == "OFFSET") {
      if (have_offset) tok.fail("second OFFSET in one joint");
      Vec3 o;
      for (int k = 0; k < 3; ++k) o[k] = length_m(tok, tok.expect_number("OFFSET value"), opt, "OFFSET value");
      m.skeleton.offsets[static_cast<size_t>(index)] = o;
      have_offset = true;
    } else if (t == "CHANNELS") {
      if (have_channels) tok.fail("second CHANNELS in one joint");
      const double n = tok.expect_number("CHANNELS count");
      if (n < 0 || n > 6 || n != std::floor(n))
        tok.fail(fmt::format("CHANNELS count {} is not an integer between 0 and 6", n));
      auto& chans = m.channels[static_cast<size_t>(index)];
      for (int k = 0; k < static_cast<int>(n); ++k) {
        std::string_view c = tok.expect("channel name");
        Channel ch;
        if (!parse_channel(c, ch))
          tok.fail(fmt::format("{} is not a channel name (CHANNELS declares {} channels; found fewer?)", quote_printable(c),
                               static_cast<int>(n)));
        for (Channel prev : chans)
          if (prev == ch) tok.fail(fmt::format("channel {} listed twice", quote_printable(c)));
        chans.push_back(ch);
      }
      have_channels = true;
    } else if (t == "JOINT") {
      std::string_view child = tok.expect("joint name");
      parse_joint(tok, m, index, std::string(child), opt, depth + 1);
    } else if (t == "End") {
      tok.expect_literal("Site");
      tok.expect_literal("{");
      tok.expect_literal("OFFSET");
      Vec3 o;
      for (int k = 0; k < 3; ++k)
        o[k] = length_m(tok, tok.expect_number("End Site OFFSET value"), opt, "End Site OFFSET value");
      m.skeleton.end_sites[static_cast<size_t>(index)] = o;
      tok.expect_literal("}");
    } else if (t == "}") {
      break;
    } else {
      tok.fail(fmt::format("unexpected {} in joint {}", quote_printable(t), quote_printable(m.skeleton.names[static_cast<size_t>(index)])));
    }
  }
  if (!have_offset) tok.fail(fmt::format("joint {} has no OFFSET", quote_printable(m.skeleton.names[static_cast<size_t>(index)])));
}

}  // namespace

Motion parse_bvh(std::string_view text, const std::string& source, const BvhReadOptions& opt) {
  Tokenizer tok(text, source);
  if (!(std::isfinite(opt.unit_to_m) && opt.unit_to_m > 0.0 && opt.unit_to_m <= 1e3))
    throw BvhError(source, fmt::format("unit_to_m {} must be in (0, 1000]", opt.unit_to_m));
  Motion m;
  tok.expect_literal("HIERARCHY");
  tok.expect_literal("ROOT");
  std::string_view root = tok.expect("root joint name");
  parse_joint(tok, m, -1, std::string(root), opt, 0);
  {
    std::string_view t = tok.next();
    if (t == "ROOT") tok.fail("more than one ROOT (only one skeleton per file is supported)");
    if (t != "MOTION")
      tok.fail(t.empty() ? "missing MOTION section" : fmt::format("expected 'MOTION', found {}", quote_printable(t)));
  }
  tok.expect_literal("Frames:");
  const double frames_d = tok.expect_number("frame count");
  if (frames_d < 0 || frames_d != std::floor(frames_d) || frames_d > kMaxFrames)
    tok.fail(fmt::format("frame count {} is not an integer between 0 and {}", frames_d, kMaxFrames));
  const int frames = static_cast<int>(frames_d);
  tok.expect_literal("Frame");
  tok.expect_literal("Time:");
  m.frame_time_s = tok.expect_number("frame time");
  if (!(m.frame_time_s >= 1e-4 && m.frame_time_s <= 1.0))
    tok.fail(fmt::format("frame time {} s is outside [0.0001, 1] s", m.frame_time_s));
  tok.finish_line();

  size_t total_channels = 0;
  for (const auto& c : m.channels) total_channels += c.size();
  const Skeleton& sk = m.skeleton;
  const size_t nj = static_cast<size_t>(sk.size());
  // Per joint: Euler order of its rotation channels in file order.
  // Each frame line takes at least two bytes, so a short file cannot make "Frames: 9999999"
  // reserve gigabytes before the truncation is found.
  m.frames.reserve(std::min(static_cast<size_t>(frames), text.size() / 2 + 1));
  std::vector<double> values(total_channels);
  for (int f = 0; f < frames; ++f) {
    std::string_view line;
    if (!tok.next_line(line))
      tok.fail(fmt::format("file ends after {} frames but 'Frames:' says {} (truncated file?)", f, frames));
    // Parse the numbers of this line.
    size_t count = 0, p = 0;
    while (p < line.size()) {
      while (p < line.size() && is_space(line[p])) ++p;
      if (p >= line.size()) break;
      size_t q = p;
      while (q < line.size() && !is_space(line[q])) ++q;
      if (count >= total_channels)
        tok.fail(fmt::format("frame {} has more than the {} values the hierarchy declares", f, total_channels));
      const std::string_view token = line.substr(p, q - p);
      if (!Tokenizer::try_number(token, values[count]))
        tok.fail_number(token, fmt::format("frame {} value {}", f, count + 1));
      ++count;
      p = q;
    }
    if (count != total_channels)
      tok.fail(fmt::format("frame {} has {} values, the hierarchy declares {} channels", f, count, total_channels));
    Pose pose;
    pose.local_rotations.assign(nj, Quat::Identity());
    pose.local_translations = sk.offsets;
    size_t v = 0;
    for (size_t j = 0; j < nj; ++j) {
      Quat q = Quat::Identity();
      for (Channel c : m.channels[j]) {
        const double val = values[v++];
        if (is_rotation(c)) {
          if (std::abs(val) > kMaxAbsRotationDeg)
            tok.fail(fmt::format("frame {}: joint {} {} {} degrees is outside the plausible range +-{} degrees", f,
                                 quote_printable(sk.names[j]), channel_name(c), val, kMaxAbsRotationDeg));
          q = q * Quat(Eigen::AngleAxisd(val * M_PI / 180.0, Vec3::Unit(axis_of(c))));
        } else {
          const double val_m = val * opt.unit_to_m;
          if (!limits::position_plausible(val_m))  // the message is built only on failure
            (void)length_m(tok, val, opt, fmt::format("frame {}: joint {} {}", f, quote_printable(sk.names[j]), channel_name(c)));
          pose.local_translations[j][axis_of(c)] = val_m;
        }
      }
      pose.local_rotations[j] = q.normalized();
    }
    m.frames.push_back(std::move(pose));
  }
  std::string_view extra;
  if (tok.next_line(extra))
    tok.fail(fmt::format("more frame lines than 'Frames: {}' declares", frames));
  if (std::string err = sk.validate(); !err.empty()) throw BvhError(source, err);
  return m;
}

Motion read_bvh(const std::filesystem::path& path, const BvhReadOptions& options) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw BvhError(path.string(), "cannot open file", "check the path and that the file is readable");
  std::stringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw BvhError(path.string(), "read error");
  return parse_bvh(ss.str(), path.string(), options);
}

std::string format_bvh(const Motion& m, double m_to_unit) {
  const Skeleton& sk = m.skeleton;
  if (std::string err = sk.validate(); !err.empty()) throw BvhError("", "cannot write BVH: " + err);
  if (m.channels.size() != static_cast<size_t>(sk.size()))
    throw BvhError("", "cannot write BVH: channel layout does not match the skeleton");
  std::vector<EulerOrder> orders(m.channels.size());
  for (size_t j = 0; j < m.channels.size(); ++j) {
    std::string order;
    for (Channel c : m.channels[j])
      if (is_rotation(c)) order += static_cast<char>('X' + axis_of(c));
    if (!order.empty() && !parse_euler_order(order, orders[j]))
      throw BvhError("", fmt::format("cannot write BVH: joint '{}' needs three distinct rotation channels, has '{}'",
                                     sk.names[j], order));
  }
  std::string out;
  out.reserve(4096 + m.frames.size() * m.channels.size() * 60);
  out += "HIERARCHY\n";
  // Children of each joint, in index order.
  std::vector<std::vector<int>> children(static_cast<size_t>(sk.size()));
  for (int j = 1; j < sk.size(); ++j) children[static_cast<size_t>(sk.parents[static_cast<size_t>(j)])].push_back(j);
  auto write_joint = [&](auto&& self, int j, int depth) -> void {
    const auto ju = static_cast<size_t>(j);
    const std::string ind(static_cast<size_t>(depth) * 2, ' ');
    out += fmt::format("{}{} {}\n{}{{\n", ind, j == 0 ? "ROOT" : "JOINT", sk.names[ju], ind);
    const Vec3 o = sk.offsets[ju] * m_to_unit;
    out += fmt::format("{}  OFFSET {:.6g} {:.6g} {:.6g}\n", ind, o.x(), o.y(), o.z());
    out += fmt::format("{}  CHANNELS {}", ind, m.channels[ju].size());
    for (Channel c : m.channels[ju]) out += fmt::format(" {}", channel_name(c));
    out += "\n";
    for (int c : children[ju]) self(self, c, depth + 1);
    if (sk.end_sites[ju]) {
      const Vec3 e = *sk.end_sites[ju] * m_to_unit;
      out += fmt::format("{}  End Site\n{}  {{\n{}    OFFSET {:.6g} {:.6g} {:.6g}\n{}  }}\n", ind, ind, ind, e.x(),
                         e.y(), e.z(), ind);
    }
    out += ind + "}\n";
  };
  write_joint(write_joint, 0, 0);
  out += fmt::format("MOTION\nFrames: {}\nFrame Time: {:.9g}\n", m.frames.size(), m.frame_time_s);
  for (const Pose& pose : m.frames) {
    bool first = true;
    for (size_t j = 0; j < m.channels.size(); ++j) {
      const Vec3 t = pose.local_translations[j] * m_to_unit;
      Vec3 e = Vec3::Zero();
      if (!m.channels[j].empty()) e = euler_deg_from_quat(pose.local_rotations[j], orders[j]);
      int r = 0;
      for (Channel c : m.channels[j]) {
        const double v = is_rotation(c) ? e[r++] : t[axis_of(c)];
        if (!first) out += ' ';
        out += fmt::format("{:.6f}", v);
        first = false;
      }
    }
    out += "\n";
  }
  return out;
}

void write_bvh(const std::filesystem::path& path, const Motion& motion, double m_to_unit) {
  const std::string text = format_bvh(motion, m_to_unit);
  std::ofstream out(path, std::ios::binary);
  if (!out) throw BvhError(path.string(), "cannot open for writing", "check that the folder exists and is writable");
  out << text;
  if (!out) throw BvhError(path.string(), "write failed", "check the free disk space");
}

}  // namespace bodyd
