// The decoder fuzz targets, shared by the brief fixed-seed loop in drivers_test
// (fuzz_test.cpp) and the libFuzzer entry points (fuzz_*.cpp, built with clang when
// -DBODYD_FUZZ=ON; docs/drivers.md says how to run them longer). Each target decodes
// arbitrary bytes and checks the decoder's promises: no crash or UB (run under the
// sanitizers), a successful decode gives a sane value, and re-encoding it reproduces the
// bytes that matter. A broken promise aborts (libFuzzer records the input).
#pragma once

#include "bodyd/drivers/hydra.h"
#include "bodyd/drivers/report.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

namespace bodyd::test {

inline void fuzz_check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "fuzz invariant broken: %s\n", what);
    std::abort();
  }
}

inline void fuzz_tracker_report(const std::uint8_t* data, std::size_t size) {
  using namespace bodyd::drivers;
  TrackerReport r;
  const ReportError e = decode_tracker_report(data, size, r);
  (void)describe_report_error(e, data, size);
  if (e != ReportError::None) return;
  fuzz_check(size == kTrackerReportSize, "accepted a report of the wrong size");
  fuzz_check(static_cast<int>(r.role) < kRoleCount, "role out of range");
  if (r.valid) {
    fuzz_check(std::abs(r.rotation.norm() - 1.0) < 1e-9, "rotation not unit length");
    fuzz_check(r.position_m.allFinite(), "position not finite");
  }
  // Round trip: re-encoding gives back the fields (the quaternion may be rounded once more).
  std::array<std::uint8_t, kTrackerReportSize> again{};
  fuzz_check(encode_tracker_report(r, again) == ReportError::None, "decoded report does not re-encode");
  TrackerReport r2;
  fuzz_check(decode_tracker_report(again.data(), again.size(), r2) == ReportError::None, "re-encoded report rejected");
  fuzz_check(r2.role == r.role && r2.valid == r.valid && r2.sequence == r.sequence &&
                 r2.device_time_us == r.device_time_us,
             "round trip changed a field");
  if (r.valid) fuzz_check((r2.position_m - r.position_m).norm() < 1e-9, "round trip changed the position");
}

inline void fuzz_hydra_report(const std::uint8_t* data, std::size_t size) {
  using namespace bodyd::drivers;
  HydraReport r;
  const HydraOptions options;
  const HydraError e = decode_hydra_report(data, size, options, r);
  (void)describe_hydra_error(e, size);
  if (e != HydraError::None) return;
  fuzz_check(size == kHydraReportSize, "accepted a Hydra report of the wrong size");
  for (const HydraController& c : r.controllers) {
    if (!c.valid) continue;
    fuzz_check(std::abs(c.rotation.norm() - 1.0) < 1e-9, "Hydra rotation not unit length");
    fuzz_check((c.position_m - options.base_position_m).norm() < 60.0, "Hydra position beyond int16 mm");
  }
}

}  // namespace bodyd::test
