// The decoder fuzz targets, shared by the brief fixed-seed loop in drivers_test
// (fuzz_test.cpp) and the libFuzzer entry points (fuzz_*.cpp, built with clang when
// -DBODYD_FUZZ=ON; docs/drivers.md says how to run them longer). Each target decodes
// arbitrary bytes and checks the decoder's promises: no crash or UB (run under the
// sanitizers), a successful decode gives a sane value, and re-encoding it reproduces the
// bytes that matter. A broken promise aborts (libFuzzer records the input).
#pragma once

#include "../fuzz/fuzz_check.h"
#include "bodyd/io/devices/hydra.h"
#include "bodyd/io/osc/osc_decode.h"
#include "bodyd/io/devices/report.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace bodyd::test {

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

// The network inputs' decode path (vrchat:, vmc:, udp:): the same bytes through the OSC packet
// decoder, the VRChat and VMC message decoders and the tracker-line decoder. Whatever is
// accepted is finite, within the limits, and unit length.
inline void fuzz_osc_input(const std::uint8_t* data, std::size_t size) {
  using namespace bodyd::drivers;
  auto check_sample = [](const Vec3& p, const Quat& q) {
    fuzz_check(p.allFinite() && p.cwiseAbs().maxCoeff() <= limits::kMaxAbsPositionM, "accepted position out of range");
    fuzz_check(std::abs(q.norm() - 1.0) < 1e-9, "accepted rotation not unit length");
  };
  std::vector<OscMessage> messages;
  std::string detail;
  const OscLimits limits;
  const InputReject r = decode_osc_packet(data, size, messages, detail, limits);
  if (r != InputReject::None) {
    fuzz_check(messages.empty(), "a rejected packet left messages behind");
    fuzz_check(!detail.empty(), "a rejected packet without a reason");
  }
  fuzz_check(messages.size() <= limits.max_messages, "more messages than the limit");
  for (const OscMessage& m : messages) {
    fuzz_check(!m.address.empty() && m.address[0] == '/', "a message without an address");
    fuzz_check(m.args.size() == m.type_tags.size(), "arguments and type tags disagree");
    InputReject why = InputReject::None;
    VrchatPose vrchat;
    const MessageUse vu = decode_vrchat_message(m, vrchat, why);
    fuzz_check((vu == MessageUse::Reject) == (why != InputReject::None), "VRChat reject without a reason");
    if (vu == MessageUse::Use) {
      const TrackerSample s = sample_from_vrchat(vrchat, 0);
      check_sample(s.position_m, s.rotation);
    }
    VmcPose vmc;
    const MessageUse mu = decode_vmc_message(m, vmc, why);
    fuzz_check((mu == MessageUse::Reject) == (why != InputReject::None), "VMC reject without a reason");
    if (mu == MessageUse::Use) check_sample(vmc.position_m, vmc.rotation);
  }
  TrackerSample s;
  std::int64_t sender_t_ns = 0;
  InputReject why = InputReject::None;
  if (decode_tracker_line(data, size, s, sender_t_ns, why, detail) == MessageUse::Use && s.valid)
    check_sample(s.position_m, s.rotation);
}

}  // namespace bodyd::test
