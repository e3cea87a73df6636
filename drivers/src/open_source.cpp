#include "bodyd/drivers/open_source.h"

#include "bodyd/drivers/device_list.h"
#include "bodyd/drivers/network_source.h"
#include "bodyd/drivers/sim_source.h"
#include "bodyd/drivers/slimevr_bridge.h"

namespace bodyd::drivers {

// The source of a parsed spec (below), before its pose frame is stamped.
static std::unique_ptr<TrackerSource> open_source_of_kind(const SourceSpec& parsed, std::string_view text,
                                                          const SourceOptions& options, std::string& error);

std::optional<PoseFrame> declared_pose_frame(SourceKind kind) {
  switch (kind) {
    case SourceKind::Replay: return std::nullopt;
    case SourceKind::Sim:
    case SourceKind::Hid:
    case SourceKind::Usb: return PoseFrame::Joint;
    case SourceKind::Vrchat:
    case SourceKind::Vmc:
    case SourceKind::Udp:
    case SourceKind::Steamvr:
    case SourceKind::Monado: return PoseFrame::Device;
  }
  return std::nullopt;
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
    error = "source \"" + text + "\": frames=" + value + " is not joint or device (docs/drivers.md, \"Device frames\")";
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

std::optional<SourceSpec> parse_source_spec(std::string_view text, std::string& error) {
  if (text == "steamvr" || text == "monado") {  // the socket's default
    SourceSpec spec;
    spec.kind = text == "steamvr" ? SourceKind::Steamvr : SourceKind::Monado;
    return spec;
  }
  struct Prefix {
    std::string_view text;
    SourceKind kind;
  };
  static constexpr Prefix kPrefixes[] = {{"replay:", SourceKind::Replay},
                                         {"sim:", SourceKind::Sim},
                                         {"hid:", SourceKind::Hid},
                                         {"usb:", SourceKind::Usb},
                                         {"vrchat:", SourceKind::Vrchat},
                                         {"vmc:", SourceKind::Vmc},
                                         {"udp:", SourceKind::Udp},
                                         {"steamvr:", SourceKind::Steamvr},
                                         {"monado:", SourceKind::Monado}};
  for (const Prefix& p : kPrefixes) {
    if (text.substr(0, p.text.size()) != p.text) continue;
    SourceSpec spec{p.kind, std::string(text.substr(p.text.size()))};
    // vrchat: and vmc: have a default address; udp: says itself what it misses.
    const bool network = p.kind == SourceKind::Vrchat || p.kind == SourceKind::Vmc || p.kind == SourceKind::Udp ||
                         p.kind == SourceKind::Steamvr || p.kind == SourceKind::Monado;
    if (spec.argument.empty() && !network) {
      error = "source \"" + std::string(text) + "\": missing " +
              (p.kind == SourceKind::Replay || p.kind == SourceKind::Sim ? "file" : "VID:PID") + " after '" +
              std::string(p.text) + "'";
      return std::nullopt;
    }
    return spec;
  }
  error = "source \"" + std::string(text) +
          "\": unknown kind; expected replay:FILE, sim:FILE.bvh, hid:VID:PID, usb:VID:PID, vrchat:[HOST:]PORT, "
          "vmc:[HOST:]PORT, udp:[HOST:]PORT, steamvr[:SOCKET] or monado[:DIR]";
  return std::nullopt;
}

std::unique_ptr<TrackerSource> open_source(std::string_view full_text, const SourceOptions& options,
                                           std::string& error) {
  std::string stripped(full_text);
  std::optional<PoseFrame> frame;
  if (!take_frames_option(stripped, frame, error)) return nullptr;
  const std::string_view text = stripped;
  const std::optional<SourceSpec> parsed = parse_source_spec(text, error);
  if (!parsed) return nullptr;
  if (!frame) frame = declared_pose_frame(parsed->kind);
  std::unique_ptr<TrackerSource> source = open_source_of_kind(*parsed, text, options, error);
  if (!source || !frame) return source;
  return std::make_unique<FrameStampSource>(std::move(source), *frame);
}

static std::unique_ptr<TrackerSource> open_source_of_kind(const SourceSpec& parsed, std::string_view text,
                                                          const SourceOptions& options, std::string& error) {
  const SourceSpec* spec = &parsed;
  switch (spec->kind) {
    case SourceKind::Replay: return open_replay_source(spec->argument, options.replay, error);
    case SourceKind::Sim: return open_sim_source(spec->argument, options.sim, options.replay, error);
    case SourceKind::Hid:
    case SourceKind::Usb: return open_device_source(text, spec->kind == SourceKind::Usb, spec->argument, error);
    case SourceKind::Vrchat:
    case SourceKind::Vmc:
    case SourceKind::Udp: {
      const NetworkKind kind = spec->kind == SourceKind::Vrchat ? NetworkKind::Vrchat
                               : spec->kind == SourceKind::Vmc  ? NetworkKind::Vmc
                                                                : NetworkKind::Udp;
      std::optional<NetworkSourceOptions> network = parse_network_spec(kind, text, spec->argument, error);
      if (!network) return nullptr;
      network->allow_remote = options.allow_remote;
      return open_network_source(*network, error);
    }
    case SourceKind::Steamvr: return slimevr::open_steamvr_source(text, spec->argument, error);
    case SourceKind::Monado: return slimevr::open_monado_source(text, spec->argument, error);
  }
  error = "source \"" + std::string(text) + "\": unknown kind";
  return nullptr;
}

}  // namespace bodyd::drivers
