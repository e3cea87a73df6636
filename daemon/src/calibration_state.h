// The daemon's calibration state (docs/daemon.md "Calibration", "Device mounting";
// docs/control.md `status`): where the height came from, what the auto calibration is doing,
// and where each role's device mounting came from, as types with their transitions, instead of
// strings. The names below are what `status` and the control replies show.
#pragma once

#include "bodyd/motion/mounting.h"
#include "bodyd/motion/tracker.h"

#include <nlohmann/json.hpp>

#include <array>
#include <string>
#include <string_view>

namespace bodyd::daemon {

// Where the standing head height came from.
enum class HeightSource {
  None,     // "none": the model's own size
  Config,   // "config": head_height_m or user_height_m
  Control,  // "control": calibrate on the control socket (a height, --from-head or --pose)
  Auto,     // "auto": the auto calibration
  File,     // "file": the mounting file's stored height
};
// The auto calibration's state.
enum class AutoCalibration {
  Off,         // "off": --no-auto-calibrate
  Waiting,     // "waiting": watching the head for a still half second
  Still,       // "still": calibrated from a still half second
  Fallback,    // "fallback": calibrated from the first seconds' percentile height
  Superseded,  // "superseded": a height came from the config, the mounting file or the control socket first
  Refused,     // "refused": no plausible standing height
};
// Where a role's device mounting came from.
enum class MountingOrigin {
  Default,  // "default": the body reference's
  Pose,     // "pose": a calibration pose measured it
  Auto,     // "auto": the auto calibration's headset refinement
  File,     // "file": config.mounting_file
};

[[nodiscard]] std::string_view name(HeightSource source);
[[nodiscard]] std::string_view name(AutoCalibration state);
[[nodiscard]] std::string_view name(MountingOrigin origin);

// The height calibration's state machine. The auto calibration runs exactly while
// auto_state() is Waiting.
class CalibrationState {
 public:
  [[nodiscard]] HeightSource source() const { return source_; }
  [[nodiscard]] AutoCalibration auto_state() const { return auto_; }
  [[nodiscard]] bool height_calibrated() const { return source_ != HeightSource::None; }
  [[nodiscard]] bool auto_waiting() const { return auto_ == AutoCalibration::Waiting; }

  // At start: a configured height (Config; the auto calibration, if on, Superseded), else the
  // auto calibration Waiting if on, else Off.
  void start(bool configured_height, bool auto_calibrate);
  // The mounting file's stored height: a measurement, so it supersedes a configured height too.
  void from_file() { supersede(HeightSource::File); }
  // A calibration from the control socket.
  void manual() { supersede(HeightSource::Control); }
  // calibrate with a height <= 0: the model's size again (the auto state stays).
  void cleared() { source_ = HeightSource::None; }
  // The auto calibration measured a height (from a still half second or the fallback) ...
  void auto_measured(bool fallback);
  // ... or found none, or its height was refused.
  void auto_refused() { auto_ = AutoCalibration::Refused; }

  // {"height_calibrated", "calibration_source", "auto_calibration"}.
  void to_json(nlohmann::json& out) const;

 private:
  void supersede(HeightSource source);
  HeightSource source_ = HeightSource::None;
  AutoCalibration auto_ = AutoCalibration::Off;
};

// Each role's mounting origin.
using MountingOrigins = std::array<MountingOrigin, kRoleCount>;

}  // namespace bodyd::daemon
