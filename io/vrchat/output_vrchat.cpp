// `--output vrchat:HOST:PORT`: VRChat's OSC trackers (bodyd/io/vrchat/vrchat.h, docs/outputs.md).
#include "bodyd/io/vrchat/vrchat.h"

#include "bodyd/io/output.h"
#include "bodyd/motion/humanoid.h"
#include "output_parts.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <cmath>
#include <memory>
#include <mutex>

namespace bodyd::daemon {

namespace vrchat {

namespace {

// kSlots as places (output_parts.h): slot N is bit N - 1.
constexpr std::array<NamedPlace, kSlots.size()> kSlotPlaces = [] {
  std::array<NamedPlace, kSlots.size()> places{};
  for (std::size_t i = 0; i < kSlots.size(); ++i) places[i] = {kSlots[i].name, kSlots[i].joint};
  return places;
}();
static_assert([] {
  for (std::size_t i = 0; i < kSlots.size(); ++i)
    if (kSlots[i].number != static_cast<int>(i) + 1) return false;
  return true;
}());
constexpr std::array<PlaceGroup, 3> kSlotGroups{{{"feet", 0b0000'0110}, {"knees", 0b0001'1000}, {"elbows", 0b1100'0000}}};
constexpr std::string_view kSlotsExpected =
    "hip, feet, knees, chest, elbows, left_foot, right_foot, left_knee, right_knee, left_elbow or right_elbow";

}  // namespace

bool parse_slots(std::string_view text, SlotMask& out, std::string& error) {
  PlaceMask mask = 0;
  const bool ok = parse_places(text, kSlotPlaces, kSlotGroups, "slot", kSlotsExpected, mask, error);
  out = static_cast<SlotMask>(mask);
  return ok;
}

std::string slot_names(SlotMask mask) { return place_names(kSlotPlaces, mask); }

TrackerPose tracker_from_bodyd(const Vec3& position_m, const Quat& rotation) {
  return TrackerPose{unity_from_bodyd(position_m), unity_euler_deg_from_quat(unity_from_bodyd(rotation))};
}

}  // namespace vrchat

namespace {

class VrchatOutput final : public OscOutput {
 public:
  VrchatOutput(std::string host, std::string port, vrchat::SlotMask slots, const OutputEnv& env)
      : OscOutput("vrchat", std::move(host), std::move(port), env), slots_(slots) {
    // Two fixed bundles: with the head messages (valid head sample) and without.
    for (OscBundle* bundle : {&with_head_, &without_head_}) {
      for (const vrchat::TrackerSlot& s : vrchat::kSlots) {
        if (!(slots_ & (1u << (s.number - 1)))) continue;
        const std::string prefix = "/tracking/trackers/" + std::to_string(s.number);
        bundle->add_floats(prefix + "/position", 3);
        bundle->add_floats(prefix + "/rotation", 3);
      }
    }
    with_head_.add_floats("/tracking/trackers/head/position", 3);
    with_head_.add_floats("/tracking/trackers/head/rotation", 3);
  }

  void set_skeleton(const Skeleton& skeleton, const std::vector<std::uint8_t>&) override {
    joints_.find(skeleton, vrchat::kSlotPlaces, slots_, name(), "slots");
  }

  // VRChat owns the head: its head message is the headset as received, and the trackers must be
  // in the same space (after a reset they were re-centred while the head was not: issue 45).
  OutputSpace space() const override { return OutputSpace::Runtime; }

  bool send(const OutputFrame& frame, std::string& out_error) override {
    if (!joints_.complete(out_error)) return false;
    const TrackerSample& head = frame.head_as_received;
    OscBundle& bundle = head.valid ? with_head_ : without_head_;
    const GlobalPose& g = frame.body.global;
    int message = 0;
    for (int j : joints_.indices()) {
      if (j >= static_cast<int>(g.positions.size())) {
        out_error = "the pose has fewer joints than its skeleton";
        return false;
      }
      write(bundle, message, vrchat::tracker_from_bodyd(g.positions[static_cast<std::size_t>(j)], g.rotations[static_cast<std::size_t>(j)]));
      message += 2;
    }
    if (head.valid) write(bundle, message, vrchat::tracker_from_bodyd(head.position_m, head.rotation));
    return sender_.send_bundle(bundle.serialise(), out_error);
  }

  nlohmann::json status() const override {
    return {{"slots", vrchat::slot_names(slots_)}, {"bundles_sent", sender_.bundles_sent()}};
  }


 private:
  static void write(OscBundle& bundle, int message, const vrchat::TrackerPose& t) {
    for (int k = 0; k < 3; ++k) {
      bundle.set_float(message, k, static_cast<float>(t.position_unity[k]));
      bundle.set_float(message + 1, k, static_cast<float>(t.euler_deg_unity[k]));
    }
  }

  vrchat::SlotMask slots_;
  OscBundle with_head_, without_head_;
  PlaceJoints joints_;  // per configured slot, in slot order
};

}  // namespace

std::unique_ptr<Output> make_vrchat_output(const OutputSpec& spec, const OutputEnv& env, std::string& error) {
  if (std::string e = check_options(spec, {"slots"}); !e.empty()) {
    error = e;
    return nullptr;
  }
  std::string host, port;
  if (!osc_target(spec, vrchat::kDefaultHost, vrchat::kDefaultPort, host, port, error)) return nullptr;
  PlaceMask slots = vrchat::kDefaultSlots;
  if (!place_option(spec, "slots", vrchat::kSlotPlaces, vrchat::kSlotGroups, "slot", vrchat::kSlotsExpected, slots, error))
    return nullptr;
  return std::make_unique<VrchatOutput>(host, port, static_cast<vrchat::SlotMask>(slots), env);
}

}  // namespace bodyd::daemon
