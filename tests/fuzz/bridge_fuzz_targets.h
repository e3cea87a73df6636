// Fuzz targets of the SlimeVR bridges' decoders (issue 17): the driver protocol's frames and
// ProtobufMessages (drivers/slimevr_bridge.h), and SolarXR MessageBundles
// (daemon/solarxr.h). Shared by the brief fixed-seed run in `make test` (brief_fuzz_test.cpp)
// and the libFuzzer executables (fuzz_main.cpp; make fuzz). A broken promise aborts.
#pragma once

#include "fuzz_check.h"
#include "bodyd/io/solarxr/solarxr.h"
#include "bodyd/io/slimevr/slimevr_bridge.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace bodyd::test {

// The bytes as a client's stream: frames one after the other, each decoded, as the bridge
// server reads them. A decoded Position or TrackerAdded re-encodes to a frame that decodes to
// the same fields.
inline void fuzz_slimevr_bridge(const std::uint8_t* data, std::size_t size) {
  namespace sv = bodyd::drivers::slimevr;
  sv::Encoder encoder;
  std::size_t at = 0;
  while (at < size) {
    const sv::FrameView f = sv::next_frame(data + at, size - at);
    if (f.result != sv::FrameResult::Frame) {
      if (f.result == sv::FrameResult::TooLong) fuzz_check(f.declared_bytes > sv::kMaxFrameBytes, "too long below the limit");
      if (f.result == sv::FrameResult::TooShort) fuzz_check(f.declared_bytes < 4, "too short at 4 or more");
      return;
    }
    fuzz_check(f.frame_bytes >= 4 && f.frame_bytes <= sv::kMaxFrameBytes && f.frame_bytes <= size - at,
                      "frame outside the bytes or the limit");
    fuzz_check(f.payload == data + at + 4 && f.payload_bytes == f.frame_bytes - 4, "payload not after the length");
    sv::Message m;
    std::string error;
    if (sv::decode_message(f.payload, f.payload_bytes, m, error)) {
      std::vector<std::uint8_t> again;
      if (m.kind == sv::Message::Kind::Position && m.has_position && std::isfinite(m.x) && std::isfinite(m.y) &&
          std::isfinite(m.z) && std::isfinite(m.qx) && std::isfinite(m.qy) && std::isfinite(m.qz) && std::isfinite(m.qw)) {
        encoder.position(again, m.tracker_id, Vec3(m.x, m.y, m.z), Quat(m.qw, m.qx, m.qy, m.qz));
        const sv::FrameView g = sv::next_frame(again.data(), again.size());
        fuzz_check(g.result == sv::FrameResult::Frame && g.frame_bytes == again.size(), "re-encoded Position is not one frame");
        sv::Message m2;
        fuzz_check(sv::decode_message(g.payload, g.payload_bytes, m2, error), "re-encoded Position rejected");
        fuzz_check(m2.kind == m.kind && m2.tracker_id == m.tracker_id && m2.x == m.x && m2.y == m.y && m2.z == m.z &&
                              m2.qx == m.qx && m2.qy == m.qy && m2.qz == m.qz && m2.qw == m.qw,
                          "Position round trip changed a field");
      } else if (m.kind == sv::Message::Kind::TrackerAdded &&
                 m.serial.size() + m.name.size() + m.manufacturer.size() < sv::kMaxFrameBytes - 64) {
        encoder.tracker_added(again, m.tracker_id, m.serial, m.name, m.role, m.manufacturer);
        const sv::FrameView g = sv::next_frame(again.data(), again.size());
        fuzz_check(g.result == sv::FrameResult::Frame, "re-encoded TrackerAdded is not one frame");
        sv::Message m2;
        fuzz_check(sv::decode_message(g.payload, g.payload_bytes, m2, error), "re-encoded TrackerAdded rejected");
        fuzz_check(m2.serial == m.serial && m2.name == m.name && m2.role == m.role && m2.tracker_id == m.tracker_id,
                          "TrackerAdded round trip changed a field");
      }
    } else {
      fuzz_check(!error.empty(), "rejected without a reason");
    }
    at += f.frame_bytes;
  }
}

// The bytes as one SolarXR frame's payload (copied to an aligned buffer, as the server does).
// bodyd's own answers decode as MessageBundles that request nothing.
inline void fuzz_solarxr(const std::uint8_t* data, std::size_t size) {
  namespace sx = bodyd::daemon::solarxr;
  const std::vector<std::uint8_t> aligned(data, data + size);
  sx::Request r;
  std::string error;
  if (sx::decode_request(aligned.data(), aligned.size(), r, error)) {
    fuzz_check(r.polls >= 0 && r.ignored >= 0, "negative counts");
    sx::Encoder enc;
    for (std::uint32_t tx : r.settings_requests) {
      const auto [p, n] = enc.settings_response(tx, sx::SteamvrToggles{});
      const std::vector<std::uint8_t> answer(p, p + n);
      sx::Request back;
      fuzz_check(sx::decode_request(answer.data(), answer.size(), back, error), "our SettingsResponse is not a bundle");
      fuzz_check(back.polls == 0 && back.settings_requests.empty() && back.ignored == 1, "our answer requests something");
    }
  } else {
    fuzz_check(!error.empty(), "rejected without a reason");
  }
}

}  // namespace bodyd::test
