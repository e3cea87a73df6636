// Opening a tracker source from its spec string (the daemon's --source values):
//
//   replay:FILE      a tracker log (docs/tracker-log.md)
//   sim:FILE.bvh     simulated head and hand trackers from a BVH clip (docs/simulator.md)
//   hid:VID:PID      HID tracker device(s) via hidapi (docs/drivers.md; VID:PID[,VID:PID...])
//   usb:VID:PID      USB tracker device(s) via libusb (docs/drivers.md)
//                    (with BODYD_FAKE_DEVICES=clip.bvh: simulated devices, fake_devices.h)
//   vrchat:[HOST:]PORT   VRChat's head and wrist poses over OSC, with OSCQuery (network_source.h)
//   vmc:[HOST:]PORT      VMC protocol HMD/controller/tracker poses (network_source.h)
//   udp:[HOST:]PORT      one tracker-log line per datagram (network_source.h)
//   steamvr[:SOCKET]     SlimeVR's OpenVR driver: headset and controllers (slimevr_bridge.h)
//   monado[:DIR]         Monado's SolarXR feeder on DIR/SlimeVRInput (slimevr_bridge.h)
//
// A spec without a known "kind:" prefix is an error (so "C:\x" or a typo is never guessed).
#pragma once

#include "bodyd/drivers/replay_source.h"
#include "bodyd/drivers/source.h"
#include "bodyd/simulators/tracker_sim.h"

#include <memory>
#include <optional>
#include <string>
#include <string_view>

namespace bodyd::drivers {

enum class SourceKind { Replay, Sim, Hid, Usb, Vrchat, Vmc, Udp, Steamvr, Monado };

struct SourceSpec {
  SourceKind kind = SourceKind::Replay;
  std::string argument;   // the file, "VID:PID", or "[HOST:]PORT[?options]" (may be empty for vrchat:, vmc:)
  // "frames=joint" or "frames=device" at the end of the spec (after '?' or '&', removed from
  // `argument`): what the source's poses are, overriding what the source declares
  // (docs/drivers.md "Device frames").
  std::optional<PoseFrame> frame;
};

// What a source of this kind delivers when the spec does not say (docs/drivers.md): the VR apps'
// inputs (vrchat:, vmc:, udp:, steamvr:, monado:) device poses; sim:, hid: and usb: joint poses;
// replay: what the log's header says (nullopt: the log decides).
[[nodiscard]] std::optional<PoseFrame> declared_pose_frame(SourceKind kind);

// Parses a spec; on failure returns nullopt and says what is wrong in `error`.
[[nodiscard]] std::optional<SourceSpec> parse_source_spec(std::string_view text, std::string& error);

struct SourceOptions {
  ReplayOptions replay;  // replay: and sim:
  SimOptions sim;        // sim:
  bool allow_remote = false;  // vrchat:, vmc:, udp: may bind to a non-loopback address (--allow-remote)
};

// Opens (does not start) the source a spec names. nullptr and `error` on failure.
[[nodiscard]] std::unique_ptr<TrackerSource> open_source(std::string_view spec, const SourceOptions& options,
                                                         std::string& error);

}  // namespace bodyd::drivers
