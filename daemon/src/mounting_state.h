// The device mountings a calibration pose learned, kept across restarts (docs/daemon.md,
// "Device mounting"; config key mounting_file). A small JSON file:
//
//   {"format": "bodyd-mounting v1", "calibrated": "2026-12-02T10:00:00Z", "head_height_m": 1.52,
//    "roles": {"head": {"measured": true, "position_m": [0, -0.1, 0.08], "rotation_xyzw": [...]},
//              "left_hand": {...}, "right_hand": {...},
//              "hips": {...}, ... only the body trackers measured (issue 44)}}
//
// Read at start, with the rules of every persisted file (docs/reliability.md, "Persisted
// files"): at most kMaxPersistedFileBytes, each field type-checked, each measured headset or
// controller mounting within the calibration pose's limits of the default (a body tracker's
// within kMaxOffsetM of its joint, turned any way); written through a private temporary
// file renamed over it (mode 0600), by the control thread (persisted_file.h).
#pragma once

#include "bodyd/inference/calibration.h"
#include "bodyd/motion/mounting.h"

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace bodyd::daemon {

struct MountingState {
  Mounting mounting;
  std::array<bool, kRoleCount> measured{};  // roles whose mounting the calibration measured
  double head_height_m = 0.0;               // 0: none stored
  std::string calibrated;                   // when (UTC, ISO 8601)
  // Read only: one line (file, field, what to do) per measured mounting that was refused because
  // it lies further from the default than a calibration pose accepts; that role reads as not
  // measured.
  std::vector<std::string> refused;
};

// Reads `path`. nullopt with `error` empty when the file does not exist; nullopt with `error`
// set (file, field, what to do) when it is too large, unreadable, not the format or holds a
// value of a wrong type or out of range. A measured mounting further from `defaults` than
// `limits` lets a calibration pose go (max_mounting_change_deg) is refused alone
// (MountingState::refused).
[[nodiscard]] std::optional<MountingState> read_mounting_state(const std::filesystem::path& path, const Mounting& defaults,
                                                             const PoseCalibrationOptions& limits, std::string& error);
// Writes `state` to `path`, creating its folders with mode 0700. Empty on success, otherwise what
// went wrong.
// Waits on the disk: never on the reconstruction thread.
[[nodiscard]] std::string write_mounting_state(const std::filesystem::path& path, const MountingState& state);

}  // namespace bodyd::daemon
