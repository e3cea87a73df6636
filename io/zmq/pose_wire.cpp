#include "bodyd/io/zmq/pose_wire.h"

#include "bodyd/motion/humanoid.h"

namespace bodyd::daemon {

protocol::SkeletonMessage skeleton_message(const Skeleton& skeleton) {
  protocol::SkeletonMessage m;
  RestPose rest;
  std::string not_humanoid;
  const bool humanoid = make_rest_pose(skeleton, rest, not_humanoid);
  for (int j = 0; j < skeleton.size(); ++j) {
    const auto i = static_cast<std::size_t>(j);
    m.names.push_back(skeleton.names[i]);
    m.parents.push_back(static_cast<std::int16_t>(skeleton.parents[i]));
    const Vec3& o = humanoid ? rest.offsets[i] : skeleton.offsets[i];
    m.offsets_m.push_back({static_cast<float>(o.x()), static_cast<float>(o.y()), static_cast<float>(o.z())});
    if (humanoid) {
      const Quat q = rest.rotations[i].normalized();
      m.rest_rotations_xyzw.push_back({static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                                       static_cast<float>(q.w())});
    }
  }
  m.skeleton_id = protocol::skeleton_id_of(m);
  return m;
}

nlohmann::json rest_rotations_json(const protocol::SkeletonMessage& skeleton) {
  if (skeleton.rest_rotations_xyzw.empty()) return nullptr;
  nlohmann::json rest = nlohmann::json::array();
  for (const auto& q : skeleton.rest_rotations_xyzw) rest.push_back({q[0], q[1], q[2], q[3]});
  return rest;
}

void fill_pose_message(const BodyPose& body, const PoseMessageContext& c, protocol::PoseMessage& out) {
  const GlobalPose& g = body.global;
  const std::size_t n = g.positions.size();
  out.joints.resize(n);
  for (std::size_t j = 0; j < n; ++j) {
    const Vec3& p = g.positions[j];
    const Quat q = g.rotations[j].normalized();
    out.joints[j].position_m = {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())};
    out.joints[j].rotation_xyzw = {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                                   static_cast<float>(q.w())};
  }
  out.seq = c.seq;
  out.t_ns = c.t_ns;
  std::uint32_t flags = 0;
  if (body.tracker_valid[0]) flags |= protocol::kFlagHeadValid;
  if (body.tracker_valid[1]) flags |= protocol::kFlagLeftHandValid;
  if (body.tracker_valid[2]) flags |= protocol::kFlagRightHandValid;
  if (c.height_calibrated) flags |= protocol::kFlagHeightCalibrated;
  if (c.offsets_configured) flags |= protocol::kFlagOffsetsCalibrated;
  out.flags = flags;
  out.skeleton_id = c.skeleton_id;
  out.foot_contact = static_cast<std::uint8_t>((body.foot_contact[0] ? protocol::kFootContactLeft : 0) |
                                               (body.foot_contact[1] ? protocol::kFootContactRight : 0));
  if (c.root_joint >= 0 && static_cast<std::size_t>(c.root_joint) < n) {
    out.root_joint = static_cast<std::uint16_t>(c.root_joint);
    out.root_position_m = out.joints[c.root_joint].position_m;
    out.root_heading_rad = protocol::heading_rad_from_rotation(out.joints[c.root_joint].rotation_xyzw);
  } else {
    out.root_joint = protocol::kNoRootJoint;
  }
}

}  // namespace bodyd::daemon
