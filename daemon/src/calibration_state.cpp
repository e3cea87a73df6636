#include "calibration_state.h"

namespace bodyd::daemon {

std::string_view name(HeightSource source) {
  switch (source) {
    case HeightSource::None: return "none";
    case HeightSource::Config: return "config";
    case HeightSource::Control: return "control";
    case HeightSource::Auto: return "auto";
    case HeightSource::File: return "file";
  }
  return "none";
}

std::string_view name(AutoCalibration state) {
  switch (state) {
    case AutoCalibration::Off: return "off";
    case AutoCalibration::Waiting: return "waiting";
    case AutoCalibration::Still: return "still";
    case AutoCalibration::Fallback: return "fallback";
    case AutoCalibration::Superseded: return "superseded";
    case AutoCalibration::Refused: return "refused";
  }
  return "off";
}

std::string_view name(MountingOrigin origin) {
  switch (origin) {
    case MountingOrigin::Default: return "default";
    case MountingOrigin::Pose: return "pose";
    case MountingOrigin::Auto: return "auto";
    case MountingOrigin::File: return "file";
  }
  return "default";
}

void CalibrationState::start(bool configured_height, bool auto_calibrate) {
  if (configured_height) {
    source_ = HeightSource::Config;
    auto_ = auto_calibrate ? AutoCalibration::Superseded : AutoCalibration::Off;
  } else {
    source_ = HeightSource::None;
    auto_ = auto_calibrate ? AutoCalibration::Waiting : AutoCalibration::Off;
  }
}

void CalibrationState::supersede(HeightSource source) {
  source_ = source;
  if (auto_ == AutoCalibration::Waiting) auto_ = AutoCalibration::Superseded;
}

void CalibrationState::auto_measured(bool fallback) {
  source_ = HeightSource::Auto;
  auto_ = fallback ? AutoCalibration::Fallback : AutoCalibration::Still;
}

void CalibrationState::to_json(nlohmann::json& out) const {
  out["height_calibrated"] = height_calibrated();
  out["calibration_source"] = std::string(name(source_));
  out["auto_calibration"] = std::string(name(auto_));
}

}  // namespace bodyd::daemon
