// SolarXR bones and codec (bodyd/io/solarxr/solarxr.h).
#include "bodyd/io/solarxr/solarxr.h"

#include "bodyd/motion/humanoid.h"
#include "solarxr_subset_generated.h"

#include <cmath>

namespace bodyd::daemon::solarxr {

namespace fb = flatbuffers;
namespace sx = solarxr_protocol;

const std::array<BoneDef, 20> kBoneDefs{{
    // body part            owner         head (a, b, mix)                 tail (a, b, mix)
    {part::kHead, "Head", "Head", "Head", 0.0, "Neck", "Neck", 0.0},
    {part::kNeck, "Neck", "Neck", "Neck", 0.0, "Chest", "Chest", 0.0},
    {part::kUpperChest, "Chest", "Chest", "Chest", 0.0, "Spine", "Spine", 0.0},
    {part::kChest, "Spine", "Spine", "Spine", 0.0, "Spine", "Hips", 0.5},
    {part::kWaist, "Hips", "Spine", "Hips", 0.5, "Hips", "Hips", 0.0},
    {part::kHip, "Hips", "Hips", "Hips", 0.0, "UpperLeg_L", "UpperLeg_R", 0.5},
    {part::kLeftShoulder, "Shoulder_L", "Shoulder_L", "Shoulder_L", 0.0, "UpperArm_L", "UpperArm_L", 0.0},
    {part::kRightShoulder, "Shoulder_R", "Shoulder_R", "Shoulder_R", 0.0, "UpperArm_R", "UpperArm_R", 0.0},
    {part::kLeftUpperArm, "UpperArm_L", "UpperArm_L", "UpperArm_L", 0.0, "LowerArm_L", "LowerArm_L", 0.0},
    {part::kRightUpperArm, "UpperArm_R", "UpperArm_R", "UpperArm_R", 0.0, "LowerArm_R", "LowerArm_R", 0.0},
    {part::kLeftLowerArm, "LowerArm_L", "LowerArm_L", "LowerArm_L", 0.0, "Hand_L", "Hand_L", 0.0},
    {part::kRightLowerArm, "LowerArm_R", "LowerArm_R", "LowerArm_R", 0.0, "Hand_R", "Hand_R", 0.0},
    // The hand has no child joint: its tail continues the forearm by 35 % of its length.
    {part::kLeftHand, "Hand_L", "Hand_L", "Hand_L", 0.0, "LowerArm_L", "Hand_L", 1.35},
    {part::kRightHand, "Hand_R", "Hand_R", "Hand_R", 0.0, "LowerArm_R", "Hand_R", 1.35},
    {part::kLeftUpperLeg, "UpperLeg_L", "UpperLeg_L", "UpperLeg_L", 0.0, "LowerLeg_L", "LowerLeg_L", 0.0},
    {part::kRightUpperLeg, "UpperLeg_R", "UpperLeg_R", "UpperLeg_R", 0.0, "LowerLeg_R", "LowerLeg_R", 0.0},
    {part::kLeftLowerLeg, "LowerLeg_L", "LowerLeg_L", "LowerLeg_L", 0.0, "Foot_L", "Foot_L", 0.0},
    {part::kRightLowerLeg, "LowerLeg_R", "LowerLeg_R", "LowerLeg_R", 0.0, "Foot_R", "Foot_R", 0.0},
    {part::kLeftFoot, "Foot_L", "Foot_L", "Foot_L", 0.0, "Toes_L", "Toes_L", 0.0},
    {part::kRightFoot, "Foot_R", "Foot_R", "Foot_R", 0.0, "Toes_R", "Toes_R", 0.0},
}};

bool BoneMap::build(const Skeleton& skeleton, std::string& error) {
  defs_.clear();
  RestPose rest;
  if (!make_rest_pose(skeleton, rest, error)) return false;
  const Quat turn(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));  // bodyd's T-pose faces +Z; OpenXR's forward is -Z
  std::vector<Resolved> defs;
  for (const BoneDef& d : kBoneDefs) {
    const int owner = skeleton.find(d.owner), ha = skeleton.find(d.head_a), hb = skeleton.find(d.head_b),
              ta = skeleton.find(d.tail_a), tb = skeleton.find(d.tail_b);
    if (owner < 0 || ha < 0 || hb < 0 || ta < 0 || tb < 0) {
      error = "the skeleton lacks a joint of SolarXR bone " + std::to_string(d.body_part) + " (" + std::string(d.owner) + ")";
      return false;
    }
    const auto at = [&](int a, int b, double mix) {
      return Vec3((1.0 - mix) * rest.global.positions[static_cast<std::size_t>(a)] +
                  mix * rest.global.positions[static_cast<std::size_t>(b)]);
    };
    const Vec3 dir = turn * (at(ta, tb, d.tail_mix) - at(ha, hb, d.head_mix));
    const double length = dir.norm();
    const Quat q_rest = length > 1e-9 ? Quat::FromTwoVectors(-Vec3::UnitY(), dir / length) : Quat::Identity();
    const Quat r_owner_rest = turn * rest.global.rotations[static_cast<std::size_t>(owner)];
    defs.push_back({d.body_part, owner, ha, hb, d.head_mix, (r_owner_rest.conjugate() * q_rest).normalized(),
                    static_cast<float>(length)});
  }
  defs_ = std::move(defs);
  return true;
}

void BoneMap::bones(const GlobalPose& pose, std::vector<Bone>& out) const {
  out.resize(defs_.size());
  for (std::size_t i = 0; i < defs_.size(); ++i) {
    const Resolved& d = defs_[i];
    const Vec3 head = (1.0 - d.head_mix) * pose.positions[static_cast<std::size_t>(d.head_a)] +
                      d.head_mix * pose.positions[static_cast<std::size_t>(d.head_b)];
    out[i].body_part = d.body_part;
    out[i].head_position_m = head;
    out[i].rotation_g = (pose.rotations[static_cast<std::size_t>(d.owner)] * d.k).normalized();
    out[i].length_m = d.length_m;
  }
}

// ---- codec -----------------------------------------------------------------------------------

bool decode_request(const std::uint8_t* data, std::size_t size, Request& out, std::string& error) {
  out = Request{};
  fb::Verifier verifier(data, size);
  if (!sx::VerifyMessageBundleBuffer(verifier)) {
    error = "not a SolarXR MessageBundle (" + std::to_string(size) + " bytes fail FlatBuffers verification)";
    return false;
  }
  const sx::MessageBundle* bundle = sx::GetMessageBundle(data);
  if (const auto* feeds = bundle->data_feed_msgs()) {
    for (const sx::data_feed::DataFeedMessageHeader* h : *feeds) {
      if (h == nullptr) continue;
      switch (h->message_type()) {
        case sx::data_feed::DataFeedMessage_PollDataFeed: ++out.polls; break;
        case sx::data_feed::DataFeedMessage_StartDataFeed: {
          const auto* start = h->message_as_StartDataFeed();
          const auto* configs = start ? start->data_feeds() : nullptr;
          if (configs == nullptr || configs->size() == 0) {
            out.stop_feed = true;
          } else {
            out.start_feed = true;
            if (const auto* c = configs->Get(0)) out.min_interval_ms = c->minimum_time_since_last();
          }
          break;
        }
        default: ++out.ignored; break;
      }
    }
  }
  if (const auto* rpcs = bundle->rpc_msgs()) {
    for (const sx::rpc::RpcMessageHeader* h : *rpcs) {
      if (h == nullptr) continue;
      const std::uint32_t tx = h->tx_id() ? h->tx_id()->id() : 0;
      if (h->message_type() == sx::rpc::RpcMessage_SettingsRequest) out.settings_requests.push_back(tx);
      else if (h->message_type() == sx::rpc::RpcMessage_HeartbeatRequest) out.heartbeat_requests.push_back(tx);
      else ++out.ignored;
    }
  }
  return true;
}

struct Encoder::Impl {
  fb::FlatBufferBuilder fbb{4096};
  std::vector<fb::Offset<sx::data_feed::tracker::TrackerData>> trackers;
  std::vector<fb::Offset<sx::data_feed::Bone>> bones;

  std::pair<const std::uint8_t*, std::size_t> finish_feed(fb::Offset<sx::data_feed::DataFeedUpdate> update) {
    const auto header = sx::data_feed::CreateDataFeedMessageHeader(fbb, sx::data_feed::DataFeedMessage_DataFeedUpdate,
                                                                    update.Union());
    const auto msgs = fbb.CreateVector(&header, 1);
    sx::MessageBundleBuilder mb(fbb);
    mb.add_data_feed_msgs(msgs);
    fbb.Finish(mb.Finish());
    return {fbb.GetBufferPointer(), fbb.GetSize()};
  }
  std::pair<const std::uint8_t*, std::size_t> finish_rpc(std::uint32_t tx_id, sx::rpc::RpcMessage type, fb::Offset<void> msg) {
    const sx::datatypes::TransactionId tx(tx_id);
    const auto header = sx::rpc::CreateRpcMessageHeader(fbb, &tx, type, msg);
    const auto msgs = fbb.CreateVector(&header, 1);
    sx::MessageBundleBuilder mb(fbb);
    mb.add_rpc_msgs(msgs);
    fbb.Finish(mb.Finish());
    return {fbb.GetBufferPointer(), fbb.GetSize()};
  }
};

Encoder::Encoder() : impl_(std::make_unique<Impl>()) {}
Encoder::~Encoder() = default;

std::pair<const std::uint8_t*, std::size_t> Encoder::update(const std::vector<SyntheticTracker>& trackers, bool with_info,
                                                            const std::vector<Bone>& bones) {
  auto& fbb = impl_->fbb;
  fbb.Clear();
  impl_->trackers.clear();
  impl_->bones.clear();
  namespace tr = sx::data_feed::tracker;
  for (const SyntheticTracker& t : trackers) {
    fb::Offset<tr::TrackerInfo> info;
    if (with_info) {
      const auto name = fbb.CreateString(t.display_name);
      tr::TrackerInfoBuilder ib(fbb);
      ib.add_body_part(static_cast<sx::datatypes::BodyPart>(t.body_part));
      ib.add_is_computed(true);
      ib.add_display_name(name);
      info = ib.Finish();
    }
    sx::datatypes::TrackerIdBuilder idb(fbb);
    idb.add_tracker_num(t.tracker_num);
    const auto id = idb.Finish();
    const sx::datatypes::math::Quat q(static_cast<float>(t.rotation.x()), static_cast<float>(t.rotation.y()),
                                      static_cast<float>(t.rotation.z()), static_cast<float>(t.rotation.w()));
    const sx::datatypes::math::Vec3f p(static_cast<float>(t.position_m.x()), static_cast<float>(t.position_m.y()),
                                       static_cast<float>(t.position_m.z()));
    tr::TrackerDataBuilder tb(fbb);
    tb.add_tracker_id(id);
    if (with_info) tb.add_info(info);
    tb.add_status(t.has_pose ? sx::datatypes::TrackerStatus_OK : sx::datatypes::TrackerStatus_DISCONNECTED);
    if (t.has_pose) {
      tb.add_rotation(&q);
      tb.add_position(&p);
    }
    impl_->trackers.push_back(tb.Finish());
  }
  for (const Bone& b : bones) {
    const sx::datatypes::math::Quat q(static_cast<float>(b.rotation_g.x()), static_cast<float>(b.rotation_g.y()),
                                      static_cast<float>(b.rotation_g.z()), static_cast<float>(b.rotation_g.w()));
    const sx::datatypes::math::Vec3f h(static_cast<float>(b.head_position_m.x()), static_cast<float>(b.head_position_m.y()),
                                       static_cast<float>(b.head_position_m.z()));
    sx::data_feed::BoneBuilder bb(fbb);
    bb.add_body_part(static_cast<sx::datatypes::BodyPart>(b.body_part));
    bb.add_rotation_g(&q);
    bb.add_bone_length(b.length_m);
    bb.add_head_position_g(&h);
    impl_->bones.push_back(bb.Finish());
  }
  const auto tv = fbb.CreateVector(impl_->trackers);
  const auto bv = fbb.CreateVector(impl_->bones);
  sx::data_feed::DataFeedUpdateBuilder ub(fbb);
  ub.add_synthetic_trackers(tv);
  ub.add_bones(bv);
  return impl_->finish_feed(ub.Finish());
}

std::pair<const std::uint8_t*, std::size_t> Encoder::settings_response(std::uint32_t tx_id, const SteamvrToggles& t) {
  auto& fbb = impl_->fbb;
  fbb.Clear();
  sx::rpc::SteamVRTrackersSettingBuilder sb(fbb);
  sb.add_waist(t.waist);
  sb.add_chest(t.chest);
  sb.add_left_foot(t.left_foot);
  sb.add_right_foot(t.right_foot);
  sb.add_left_knee(t.left_knee);
  sb.add_right_knee(t.right_knee);
  sb.add_left_elbow(t.left_elbow);
  sb.add_right_elbow(t.right_elbow);
  sb.add_left_hand(t.left_hand);
  sb.add_right_hand(t.right_hand);
  const auto steamvr = sb.Finish();
  sx::rpc::SettingsResponseBuilder rb(fbb);
  rb.add_steam_vr_trackers(steamvr);
  return impl_->finish_rpc(tx_id, sx::rpc::RpcMessage_SettingsResponse, rb.Finish().Union());
}

std::pair<const std::uint8_t*, std::size_t> Encoder::heartbeat_response(std::uint32_t tx_id) {
  auto& fbb = impl_->fbb;
  fbb.Clear();
  sx::rpc::HeartbeatResponseBuilder hb(fbb);
  return impl_->finish_rpc(tx_id, sx::rpc::RpcMessage_HeartbeatResponse, hb.Finish().Union());
}

}  // namespace bodyd::daemon::solarxr
