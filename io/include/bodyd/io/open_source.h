// Opening a tracker source from its spec string (the daemon's --source values). Every scheme is
// one row of the source registry (io/sources.cpp, source_schemes() below):
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
//
// How to add a source (one new file plus one row; docs/architecture.md, "A new tracker source"):
//   1. io/NAME/NAME_source.cpp (the protocol's own folder, docs/architecture.md): a class implementing TrackerSource (source.h) and a factory
//        std::unique_ptr<TrackerSource> open_NAME_spec(const SourceSpec&, const SourceOptions&, std::string& error);
//      that returns nullptr with `error` set ("source \"SPEC\": what is wrong, what to do") when
//      the spec is bad; optionally a check of the argument that opens nothing,
//        std::string check_NAME_spec(const SourceSpec&);
//   2. One row in the table of io/sources.cpp (declaring the two functions above it):
//        {"NAME", "NAME:ARG", required argument, bare, declared frame, open_NAME_spec, check_NAME_spec}.
//      The error text's list of schemes and the daemon's --source help are made from the rows.
//   3. The file in io/CMakeLists.txt; the spec in docs/drivers.md.
//   Options a source needs from the daemon's config travel in SourceOptions (below), filled
//   in daemon/src/daemon.cpp. A protocol over UDP is a decoder instead (network_source.h).
#pragma once

#include "bodyd/io/replay/replay_source.h"
#include "bodyd/io/source.h"
#include "bodyd/simulators/tracker_sim.h"

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::drivers {

struct SourceScheme;

struct SourceSpec {
  const SourceScheme* scheme = nullptr;  // its row in source_schemes() (set by parse_source_spec)
  std::string text;       // the spec as given, without a "frames=" option: the source's name
  std::string argument;   // the file, "VID:PID", or "[HOST:]PORT[?options]" (may be empty for vrchat:, vmc:)
  // "frames=joint" or "frames=device" at the end of the spec (after '?' or '&', removed from
  // `text` and `argument`): what the source's poses are, overriding what the source declares
  // (docs/drivers.md "Device frames").
  std::optional<PoseFrame> frame;
};

struct SourceOptions {
  ReplayOptions replay;  // replay: and sim:
  SimOptions sim;        // sim:
  bool allow_remote = false;  // vrchat:, vmc:, udp: may bind to a non-loopback address (--allow-remote)
};

// Opens (does not start) the source; nullptr and `error` when the spec is bad.
using SourceFactory = std::unique_ptr<TrackerSource> (*)(const SourceSpec& spec, const SourceOptions& options,
                                                         std::string& error);
// Checks what can be checked without opening anything (the daemon's config check, exit 2):
// empty, or what is wrong.
using SourceCheck = std::string (*)(const SourceSpec& spec);

// One row of the source registry (io/sources.cpp).
struct SourceScheme {
  std::string_view scheme;  // "replay": specs start "replay:"
  std::string_view syntax;  // "replay:FILE": listed in the unknown-kind error and the --source help
  // What the argument is when it may not be empty ("file", "VID:PID": "missing file after
  // 'replay:'"); empty: the source has a default (vrchat: and vmc:) or says itself what it misses.
  std::string_view required_argument;
  bool bare = false;  // the scheme alone ("steamvr", no ':') is the spec with the default argument
  // What the source delivers when the spec does not say (docs/drivers.md, "Device frames"): a
  // device that reports its own pose (a headset at the eyes, a controller's grip) Device; a
  // source that delivers the joints Joint; nullopt: the source stamps each sample itself
  // (replay: what the log's header says).
  std::optional<PoseFrame> frame;
  SourceFactory open = nullptr;
  SourceCheck check = nullptr;  // nullptr: nothing to check before opening
};

// The registered sources, in the order the help lists them.
[[nodiscard]] const std::vector<SourceScheme>& source_schemes();

// The schemes' syntaxes, "replay:FILE, sim:FILE.bvh, ... or monado[:DIR]" (`last` before the
// last one: " or " in the error text, ", " in the --source help).
[[nodiscard]] std::string source_syntax_list(std::string_view last = " or ");

// What a source of this scheme delivers when the spec does not say (SourceScheme::frame).
[[nodiscard]] std::optional<PoseFrame> declared_pose_frame(const SourceScheme& scheme);

// Parses a spec (a "frames=" option is taken off and kept in `frame`); on failure returns
// nullopt and says what is wrong in `error`.
[[nodiscard]] std::optional<SourceSpec> parse_source_spec(std::string_view text, std::string& error);

// Parses a spec and checks it as far as it can without opening it (a missing file is found
// when it is opened). Empty, or what is wrong.
[[nodiscard]] std::string check_source_spec(std::string_view text);

// Opens (does not start) the source a spec names. nullptr and `error` on failure.
[[nodiscard]] std::unique_ptr<TrackerSource> open_source(std::string_view spec, const SourceOptions& options,
                                                         std::string& error);

}  // namespace bodyd::drivers
