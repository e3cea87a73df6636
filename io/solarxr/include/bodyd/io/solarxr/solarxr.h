// SolarXR for Monado's SolarXR driver (`--output monado`, docs/protocol-solarxr.md): bodyd's
// pose as SolarXR bones, and the pure codec of the messages bodyd reads and writes (FlatBuffers
// through the classes flatc generates at build time from io/solarxr/solarxr_subset.fbs).
//
// The bone convention (SolarXR's Bone table): a bone has a head (the end nearer the headset) at
// head_position_g, a length, and a global rotation rotation_g whose identity points the bone's
// tail along -Y from its head. bodyd's bones, each carried by one joint O of the skeleton:
//
//   rotation_g = R_O * K,  K = R_O_rest^-1 * Q_rest
//
// with R_O the joint's global rotation (the pose stream's), R_O_rest its rotation in bodyd's
// reference T-pose (bodyd/motion/humanoid.h) turned to face -Z (OpenXR's forward), and Q_rest
// the shortest rotation taking -Y to the bone's direction in that T-pose. So in the T-pose
// facing -Z the spine and leg bones are the identity, the arms a quarter turn about Z, and the
// tail is always head + rotation_g * (0, -length, 0) (for limb bones: the child joint).
#pragma once

#include "bodyd/base/non_copyable.h"
#include "bodyd/motion/skeleton.h"

#include <array>
#include <memory>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::daemon::solarxr {

// SolarXR's BodyPart values (schema/datatypes/datatypes.fbs).
namespace part {
inline constexpr std::uint8_t kHead = 1, kNeck = 2, kChest = 3, kWaist = 4, kHip = 5, kLeftUpperLeg = 6,
                              kRightUpperLeg = 7, kLeftLowerLeg = 8, kRightLowerLeg = 9, kLeftFoot = 10,
                              kRightFoot = 11, kLeftLowerArm = 14, kRightLowerArm = 15, kLeftUpperArm = 16,
                              kRightUpperArm = 17, kLeftHand = 18, kRightHand = 19, kLeftShoulder = 20,
                              kRightShoulder = 21, kUpperChest = 22;
}

struct Bone {
  std::uint8_t body_part = 0;
  Quat rotation_g = Quat::Identity();
  float length_m = 0.0f;
  Vec3 head_position_m = Vec3::Zero();
};

// Where each bone of bodyd's skeleton starts and which joint carries it (docs/protocol-solarxr.md):
// head = (1 - head_mix) * joint head_a + head_mix * joint head_b; tail in the rest pose the
// same way from tail_a / tail_b; carried by joint `owner`.
struct BoneDef {
  std::uint8_t body_part;
  std::string_view owner;
  std::string_view head_a, head_b;
  double head_mix;
  std::string_view tail_a, tail_b;
  double tail_mix;
};
extern const std::array<BoneDef, 20> kBoneDefs;

// The bones of one skeleton: constants from its T-pose, then per pose.
class BoneMap {
 public:
  // False (and `error`) when the skeleton is not bodyd's humanoid.
  [[nodiscard]] bool build(const Skeleton& skeleton, std::string& error);
  [[nodiscard]] bool ready() const { return !defs_.empty(); }
  // `pose` in the output's space (OutputFrame::body). `out` has one bone per kBoneDefs entry.
  void bones(const GlobalPose& pose, std::vector<Bone>& out) const;

 private:
  struct Resolved {
    std::uint8_t body_part;
    int owner, head_a, head_b;
    double head_mix;
    Quat k;
    float length_m;
  };
  std::vector<Resolved> defs_;
};

// ---- the codec --------------------------------------------------------------------------------

// What a client asked for in one MessageBundle.
struct Request {
  int polls = 0;              // PollDataFeed messages (each wants one DataFeedUpdate)
  bool start_feed = false;    // a StartDataFeed (updates at bodyd's rate from now on)
  bool stop_feed = false;     // a StartDataFeed with no data feeds
  std::uint16_t min_interval_ms = 0;  // the StartDataFeed's first config's minimum_time_since_last
  std::vector<std::uint32_t> settings_requests;   // tx ids of SettingsRequests
  std::vector<std::uint32_t> heartbeat_requests;  // tx ids of HeartbeatRequests
  int ignored = 0;            // other messages (data feed or rpc) bodyd does not serve
};

// Verifies and decodes one frame's payload. False (and `error`) when it is not a MessageBundle.
[[nodiscard]] bool decode_request(const std::uint8_t* data, std::size_t size, Request& out, std::string& error);

// A synthetic tracker (a `trackers=` role of the output).
struct SyntheticTracker {
  std::uint8_t tracker_num = 0;
  std::uint8_t body_part = 0;
  std::string display_name;
  bool has_pose = false;
  Vec3 position_m = Vec3::Zero();
  Quat rotation = Quat::Identity();
};

struct SteamvrToggles {
  bool waist = false, chest = false, left_foot = false, right_foot = false, left_knee = false, right_knee = false,
       left_elbow = false, right_elbow = false, left_hand = false, right_hand = false;
};

// Builds MessageBundles. Reuses its buffer: no allocation once warmed up. The returned span is
// valid until the next call.
class Encoder : NonCopyable {
 public:
  Encoder();
  ~Encoder();
  // One DataFeedUpdate with `trackers` (their info when with_info) and `bones`.
  std::pair<const std::uint8_t*, std::size_t> update(const std::vector<SyntheticTracker>& trackers, bool with_info,
                                                     const std::vector<Bone>& bones);
  std::pair<const std::uint8_t*, std::size_t> settings_response(std::uint32_t tx_id, const SteamvrToggles& toggles);
  std::pair<const std::uint8_t*, std::size_t> heartbeat_response(std::uint32_t tx_id);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace bodyd::daemon::solarxr
