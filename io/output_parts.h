// What several outputs share (docs/outputs.md), each written once:
//   - named places (trackers, slots), one bit each: the `trackers` / `slots` option lists, their
//     names back for status, the skeleton joints they follow;
//   - the body trackers of the steamvr and monado outputs (the same names, joints and option);
//   - OscOutput: the host, port and socket of an OSC output (vrchat, vmc).
#pragma once

#include "bodyd/io/output.h"
#include "osc/osc_sender.h"

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::daemon {

using PlaceMask = std::uint16_t;

// A place an output sends to: its name in the option, the skeleton joint it follows. In a list
// of places, place i is bit i of a PlaceMask.
struct NamedPlace {
  std::string_view name;
  std::string_view joint;  // docs/conventions.md names
};
// A group name of an option list ("feet") and the places' bits it stands for.
struct PlaceGroup {
  std::string_view name;
  PlaceMask bits;
};

// Parses a comma-separated list of names of `places` and `groups` into their bits. False with
// `error` = WHAT "NAME": expected EXPECTED at an unknown or empty name.
[[nodiscard]] bool parse_places(std::string_view text, std::span<const NamedPlace> places, std::span<const PlaceGroup> groups,
                                std::string_view what, std::string_view expected, PlaceMask& out, std::string& error);
// Option `key` of `spec` parsed by parse_places (`out` keeps its default when it is not there).
// False with `error` naming the spec.
[[nodiscard]] bool place_option(const OutputSpec& spec, std::string_view key, std::span<const NamedPlace> places,
                                std::span<const PlaceGroup> groups, std::string_view what, std::string_view expected,
                                PlaceMask& out, std::string& error);
// "a,b,c": the names of the places in `mask`, in order.
[[nodiscard]] std::string place_names(std::span<const NamedPlace> places, PlaceMask mask);
// The skeleton's index of the joint of each place in `mask`, in order (-1 where it has none);
// `missing` = "A, B", the joints it lacks ("" when it has all).
[[nodiscard]] std::vector<int> place_joints(const Skeleton& skeleton, std::span<const NamedPlace> places, PlaceMask mask,
                                            std::string& missing);

// The trackers the steamvr and monado outputs can announce, bit i for kBodyTrackers[i]; each
// output gives them its protocol's role numbers in the same order (docs/outputs.md).
inline constexpr std::array<NamedPlace, 8> kBodyTrackers{{{"waist", "Hips"},
                                                          {"left_foot", "Foot_L"},
                                                          {"right_foot", "Foot_R"},
                                                          {"chest", "Chest"},
                                                          {"left_knee", "LowerLeg_L"},
                                                          {"right_knee", "LowerLeg_R"},
                                                          {"left_elbow", "LowerArm_L"},
                                                          {"right_elbow", "LowerArm_R"}}};
inline constexpr PlaceMask kDefaultBodyTrackers = 0b0000'0111;  // waist and feet
// The spec of a steamvr or monado output: its options checked (only `trackers`), its `trackers`
// list (default kDefaultBodyTrackers: waist and feet; groups feet, knees, elbows; "hip", VRChat's
// name, for waist) and its socket, `socket_of(spec.target, e)` (empty and `e` when it cannot
// be). False with `error` naming the spec.
using SocketOfTarget = std::string (*)(const std::string& target, std::string& error);
[[nodiscard]] bool body_tracker_output_spec(const OutputSpec& spec, SocketOfTarget socket_of, PlaceMask& out_mask,
                                            std::string& out_socket, std::string& error);

// The joints of an output's places, found again for each skeleton (set_skeleton), and whether
// the skeleton has them all (send).
class PlaceJoints {
 public:
  // Logs, naming `output` and `what` ("trackers"), when the skeleton lacks some.
  void find(const Skeleton& skeleton, std::span<const NamedPlace> places, PlaceMask mask, const std::string& output,
            std::string_view what);
  // False with `out_error` naming the missing joints.
  [[nodiscard]] bool complete(std::string& out_error) const;
  // Per place in the mask, in order; -1 where the skeleton has none.
  [[nodiscard]] const std::vector<int>& indices() const { return indices_; }

 private:
  std::vector<int> indices_;
  std::string missing_;
};

// An output that sends OSC bundles over UDP to HOST:PORT (osc_sender.h): its name, open() and
// close(); the derived output builds and sends the bundles through sender_.
class OscOutput : public Output {
 public:
  OscOutput(std::string_view scheme, std::string host, std::string port, const OutputEnv& env);
  [[nodiscard]] std::string name() const override;
  [[nodiscard]] std::string open() override;
  void close() override { sender_.close(); }

 protected:
  OscSender sender_;

 private:
  std::string scheme_, host_, port_;
  bool allow_remote_ = false;  // --allow-remote (osc_sender.h)
};

// An OSC output's target, HOST:PORT with the defaults filling what is left out. False with
// `error` naming the spec.
[[nodiscard]] bool osc_target(const OutputSpec& spec, std::string_view default_host, int default_port, std::string& host,
                              std::string& port, std::string& error);

}  // namespace bodyd::daemon
