// What several outputs share (output_parts.h).
#include "output_parts.h"


#include <spdlog/spdlog.h>

namespace bodyd::daemon {

bool parse_places(std::string_view text, std::span<const NamedPlace> places, std::span<const PlaceGroup> groups,
                  std::string_view what, std::string_view expected, PlaceMask& out, std::string& error) {
  out = 0;
  std::string_view rest = text;
  while (true) {
    const auto comma = rest.find(',');
    const std::string_view name = rest.substr(0, comma);
    PlaceMask bits = 0;
    for (const PlaceGroup& g : groups)
      if (g.name == name) bits = g.bits;
    for (std::size_t i = 0; i < places.size(); ++i)
      if (places[i].name == name) bits = static_cast<PlaceMask>(1u << i);
    if (bits == 0) {
      error = std::string(what) + " \"" + std::string(name) + "\": expected " + std::string(expected);
      return false;
    }
    out |= bits;
    if (comma == std::string_view::npos) return true;
    rest = rest.substr(comma + 1);
  }
}

bool place_option(const OutputSpec& spec, std::string_view key, std::span<const NamedPlace> places,
                  std::span<const PlaceGroup> groups, std::string_view what, std::string_view expected, PlaceMask& out,
                  std::string& error) {
  const auto it = spec.options.find(std::string(key));
  if (it == spec.options.end()) return true;
  if (parse_places(it->second, places, groups, what, expected, out, error)) return true;
  error = "--output " + spec.text + ": " + error;
  return false;
}

std::string place_names(std::span<const NamedPlace> places, PlaceMask mask) {
  std::string names;
  for (std::size_t i = 0; i < places.size(); ++i)
    if (mask & (1u << i)) names += (names.empty() ? "" : ",") + std::string(places[i].name);
  return names;
}

std::vector<int> place_joints(const Skeleton& skeleton, std::span<const NamedPlace> places, PlaceMask mask,
                              std::string& missing) {
  std::vector<int> joints;
  missing.clear();
  for (std::size_t i = 0; i < places.size(); ++i) {
    if (!(mask & (1u << i))) continue;
    const int j = skeleton.find(places[i].joint);
    if (j < 0) missing += (missing.empty() ? "" : ", ") + std::string(places[i].joint);
    joints.push_back(j);
  }
  return joints;
}

bool body_tracker_output_spec(const OutputSpec& spec, SocketOfTarget socket_of, PlaceMask& out_mask,
                              std::string& out_socket, std::string& error) {
  static constexpr std::array<PlaceGroup, 4> kGroups{{{"feet", 0b0000'0110},
                                                      {"knees", 0b0011'0000},
                                                      {"elbows", 0b1100'0000},
                                                      {"hip", 0b0000'0001}}};  // VRChat's slot name, accepted too
  if (std::string e = check_options(spec, {"trackers"}); !e.empty()) {
    error = e;
    return false;
  }
  out_mask = kDefaultBodyTrackers;
  if (!place_option(spec, "trackers", kBodyTrackers, kGroups, "tracker",
                    "waist, feet, knees, chest, elbows, left_foot, right_foot, left_knee, right_knee, left_elbow or "
                    "right_elbow",
                    out_mask, error))
    return false;
  std::string e;
  out_socket = socket_of(spec.target, e);
  if (out_socket.empty()) {
    error = "--output " + spec.text + ": " + e;
    return false;
  }
  return true;
}

void PlaceJoints::find(const Skeleton& skeleton, std::span<const NamedPlace> places, PlaceMask mask,
                       const std::string& output, std::string_view what) {
  indices_ = place_joints(skeleton, places, mask, missing_);
  if (!missing_.empty())
    spdlog::error("--output {}: the skeleton has no joint {} for the configured {}; nothing is sent", output, missing_, what);
}

bool PlaceJoints::complete(std::string& out_error) const {
  if (missing_.empty()) return true;
  out_error = "the skeleton has no joint " + missing_;
  return false;
}

OscOutput::OscOutput(std::string_view scheme, std::string host, std::string port, const OutputEnv& env)
    : scheme_(scheme), host_(std::move(host)), port_(std::move(port)), allow_remote_(env.allow_remote) {}

std::string OscOutput::name() const {
  return scheme_ + ":" + (sender_.address().empty() ? host_ + ":" + port_ : sender_.address());
}

std::string OscOutput::open() {
  return sender_.open(host_, port_, "--output " + scheme_ + ":" + host_ + ":" + port_, allow_remote_);
}

bool osc_target(const OutputSpec& spec, std::string_view default_host, int default_port, std::string& host,
                std::string& port, std::string& error) {
  return split_host_port(spec.target, default_host, default_port, host, port, "--output " + spec.text, error);
}

}  // namespace bodyd::daemon
