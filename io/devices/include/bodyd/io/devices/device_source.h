// What the device drivers (HID, USB, simulated devices behind fake transports) report
// beyond SourceStatus: counters a test or the log can check. A DeviceSource is a
// TrackerSource; the daemon needs only the TrackerSource part.
#pragma once

#include "bodyd/io/source.h"

#include <cstdint>

namespace bodyd::drivers {

struct DeviceStats {
  std::uint64_t reports = 0;        // reports decoded (a Hydra report counts once, for two samples)
  std::uint64_t decode_errors = 0;  // reports rejected by the decoder (short, garbage, bad version...)
  std::uint64_t lost_reports = 0;   // gaps in the devices' sequence numbers
  std::uint64_t clock_jumps = 0;    // device clock restarted or jumped (its timestamps only; t_ns is host time)
  std::uint64_t connects = 0;       // devices opened
  std::uint64_t disconnects = 0;    // devices lost (unplugged, read error)
  std::uint64_t stalls = 0;         // an open device went quiet for longer than the stall timeout
  int devices_open = 0;             // now
};

class DeviceSource : public TrackerSource {
 public:
  [[nodiscard]] virtual DeviceStats stats() const = 0;
};

// A USB vendor/product ID pair, e.g. 1209:B0D1.
struct DeviceId {
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  friend bool operator==(const DeviceId&, const DeviceId&) = default;
};

}  // namespace bodyd::drivers
