#include "bodyd/io/open_source.h"

#include "bodyd/motion/printable.h"

namespace bodyd::drivers {

std::optional<PoseFrame> declared_pose_frame(const SourceScheme& scheme) { return scheme.frame; }

std::string source_syntax_list(std::string_view last) {
  const std::vector<SourceScheme>& schemes = source_schemes();
  std::string text;
  for (std::size_t i = 0; i < schemes.size(); ++i) {
    if (i > 0) text += i + 1 == schemes.size() ? std::string(last) : std::string(", ");
    text += schemes[i].syntax;
  }
  return text;
}

namespace {

// Takes a trailing "frames=joint|device" option off `text` ("...?frames=x" or "...&frames=x").
// Returns false (error set) for a bad value.
bool take_frames_option(std::string& text, std::optional<PoseFrame>& frame, std::string& error) {
  const std::size_t at = text.rfind("frames=");
  if (at == std::string::npos || at == 0 || (text[at - 1] != '?' && text[at - 1] != '&')) return true;
  const std::string value = text.substr(at + 7);
  frame = pose_frame_from_name(value);
  if (!frame) {
    error = "source \"" + printable(text, 200) + "\": frames=" + printable(value) +
            " is not joint or device (docs/drivers.md, \"Device frames\")";
    return false;
  }
  text.erase(at - 1);
  return true;
}

// Stamps every sample of the inner source with one PoseFrame.
class FrameStampSink final : public SampleSink {
 public:
  FrameStampSink(SampleSink& inner, PoseFrame frame) : inner_(inner), frame_(frame) {}
  void push(const SourceSample& s) override { inner_.push(stamped(s)); }
  bool push_wait(const SourceSample& s, std::chrono::nanoseconds timeout) override {
    return inner_.push_wait(stamped(s), timeout);
  }

 private:
  SourceSample stamped(const SourceSample& s) const {
    SourceSample out = s;
    out.sample.frame = frame_;
    return out;
  }
  SampleSink& inner_;
  PoseFrame frame_;
};

class FrameStampSource final : public TrackerSource {
 public:
  FrameStampSource(std::unique_ptr<TrackerSource> inner, PoseFrame frame) : inner_(std::move(inner)), frame_(frame) {}
  ~FrameStampSource() override { stop(); }
  const std::string& name() const override { return inner_->name(); }
  std::string start(SampleSink& sink, std::uint16_t source_index) override {
    sink_.emplace(sink, frame_);
    return inner_->start(*sink_, source_index);
  }
  void stop() override { inner_->stop(); }
  SourceStatus status() const override { return inner_->status(); }

 private:
  std::unique_ptr<TrackerSource> inner_;
  PoseFrame frame_;
  std::optional<FrameStampSink> sink_;
};

}  // namespace

std::optional<SourceSpec> parse_source_spec(std::string_view full_text, std::string& error) {
  SourceSpec spec;
  spec.text = std::string(full_text);
  if (!take_frames_option(spec.text, spec.frame, error)) return std::nullopt;
  const std::string_view text = spec.text;
  for (const SourceScheme& row : source_schemes()) {
    if (row.bare && text == row.scheme) {  // the default argument
      spec.scheme = &row;
      return spec;
    }
    if (text.size() <= row.scheme.size() || text.substr(0, row.scheme.size()) != row.scheme ||
        text[row.scheme.size()] != ':')
      continue;
    spec.scheme = &row;
    spec.argument = std::string(text.substr(row.scheme.size() + 1));
    if (spec.argument.empty() && !row.required_argument.empty()) {
      error = "source \"" + printable(spec.text, 200) + "\": missing " + std::string(row.required_argument) + " after '" +
              std::string(row.scheme) + ":'";
      return std::nullopt;
    }
    return spec;
  }
  error = "source \"" + printable(spec.text, 200) + "\": unknown kind; expected " + source_syntax_list(" or ");
  return std::nullopt;
}

namespace {

// A spec's error quotes the spec, which may hold any byte (a config file, a pasted command line):
// every byte that is not printable ASCII is escaped, whichever row's parser wrote the message.
std::string escaped(std::string error) { return printable(error, error.size()); }

}  // namespace

std::string check_source_spec(std::string_view text) {
  std::string error;
  const std::optional<SourceSpec> spec = parse_source_spec(text, error);
  if (!spec) return escaped(error);
  return escaped(spec->scheme->check ? spec->scheme->check(*spec) : std::string());
}

std::unique_ptr<TrackerSource> open_source(std::string_view text, const SourceOptions& options, std::string& error) {
  const std::optional<SourceSpec> spec = parse_source_spec(text, error);
  if (!spec) {
    error = escaped(error);
    return nullptr;
  }
  const std::optional<PoseFrame> frame = spec->frame ? spec->frame : declared_pose_frame(*spec->scheme);
  std::unique_ptr<TrackerSource> source = spec->scheme->open(*spec, options, error);
  if (!source && error.empty()) error = "source \"" + spec->text + "\": cannot open the source";
  if (!source) error = escaped(error);
  if (!source || !frame) return source;
  return std::make_unique<FrameStampSource>(std::move(source), *frame);
}

}  // namespace bodyd::drivers
