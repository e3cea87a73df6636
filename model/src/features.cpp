#include "bodyd/inference/features.h"

#include <fmt/format.h>

#include <cmath>

namespace bodyd::features {
namespace {

// The head's orientation when upright and facing +Z, in this skeleton's head frame:
// the head's local +X (the neck-to-head bone) points up, its local +Y points forward
// (measured on walking clips of the data: local +Y is the walking direction within ~10 deg).
const Quat& head_reference() {
  static const Quat q = [] {
    Mat3 R;
    R.col(0) = Vec3::UnitY();  // local X -> up
    R.col(1) = Vec3::UnitZ();  // local Y -> forward
    R.col(2) = Vec3::UnitX();  // local Z = X x Y -> world X
    return Quat(R).normalized();
  }();
  return q;
}

}  // namespace

std::string check_skeleton(const Skeleton& sk) {
  if (std::string err = sk.validate(); !err.empty()) return err;
  if (sk.size() != static_cast<int>(kJointNames.size()))
    return fmt::format("skeleton has {} joints, the features need {}", sk.size(), kJointNames.size());
  for (int i = 0; i < sk.size(); ++i)
    if (sk.names[static_cast<size_t>(i)] != kJointNames[static_cast<size_t>(i)])
      return fmt::format("joint {} is '{}', the features need '{}'", i, sk.names[static_cast<size_t>(i)],
                         kJointNames[static_cast<size_t>(i)]);
  return {};
}

double head_yaw(const Quat& R_world_head) {
  // Twist about world +Y of the rotation taking the reference orientation to the current one.
  const Quat rel = (R_world_head * head_reference().conjugate()).normalized();
  return 2.0 * std::atan2(rel.y(), rel.w());
}

Canonical canonical_from_head(const Vec3& head_position_m, const Quat& R_world_head) {
  Canonical c;
  c.yaw_rad = std::remainder(head_yaw(R_world_head), 2.0 * M_PI);
  c.origin_m = Vec3(head_position_m.x(), 0.0, head_position_m.z());
  c.R_world_canon = quat_from_yaw(c.yaw_rad);
  c.R_canon_world = c.R_world_canon.conjugate();
  return c;
}

void encode_joint(int j, const Vec3& p, const Quat& q, const Canonical& c, Frame out) {
  float* o = out.data() + joint_offset(j);
  const Vec3 pc = c.R_canon_world * (p - c.origin_m);
  const Vec6 r = rot6d_from_quat(c.R_canon_world * q);
  for (int k = 0; k < 3; ++k) o[k] = static_cast<float>(pc[k]);
  for (int k = 0; k < 6; ++k) o[3 + k] = static_cast<float>(r[k]);
}

void encode_pose(const GlobalPose& g, const std::array<bool, 2>& contact, const Canonical& c, Frame out) {
  for (int j = 1; j <= kBodyJoints; ++j)
    encode_joint(j, g.positions[static_cast<size_t>(j)], g.rotations[static_cast<size_t>(j)], c, out);
  out[kContactOffset] = contact[0] ? 1.0f : 0.0f;
  out[kContactOffset + 1] = contact[1] ? 1.0f : 0.0f;
}

void world_entries(const GlobalPose& g, WorldEntries& out) {
  for (int j = 1; j <= kBodyJoints; ++j) {
    const auto i = static_cast<size_t>(j - 1) * 3;
    const Mat3 R = g.rotations[static_cast<size_t>(j)].normalized().toRotationMatrix();
    out.v[i] = g.positions[static_cast<size_t>(j)];
    out.v[i + 1] = R.col(0);
    out.v[i + 2] = R.col(1);
  }
}

void encode_world_entries(const WorldEntries& w, const std::array<bool, 2>& contact, const Canonical& c, Frame out) {
  // encode_joint's R_canon_world * (p - origin) and rot6d(R_canon_world * q), the latter as the
  // rotated columns of q's matrix.
  const Mat3 M = c.R_canon_world.toRotationMatrix();
  for (int j = 1; j <= kBodyJoints; ++j) {
    const auto i = static_cast<size_t>(j - 1) * 3;
    float* o = out.data() + joint_offset(j);
    const Vec3 p = M * (w.v[i] - c.origin_m), c0 = M * w.v[i + 1], c1 = M * w.v[i + 2];
    for (int k = 0; k < 3; ++k) {
      o[k] = static_cast<float>(p[k]);
      o[3 + k] = static_cast<float>(c0[k]);
      o[6 + k] = static_cast<float>(c1[k]);
    }
  }
  out[kContactOffset] = contact[0] ? 1.0f : 0.0f;
  out[kContactOffset + 1] = contact[1] ? 1.0f : 0.0f;
}

void decode_joint(int j, ConstFrame in, const Canonical& c, Vec3& out_p, Quat& out_q) {
  const float* o = in.data() + joint_offset(j);
  Vec6 r;
  for (int k = 0; k < 6; ++k) r[k] = o[3 + k];
  out_p = c.R_world_canon * Vec3(o[0], o[1], o[2]) + c.origin_m;
  out_q = (c.R_world_canon * quat_from_rot6d(r)).normalized();
}

void decode_pose(const Skeleton& sk, ConstFrame in, const Canonical& c, Pose& out, std::array<bool, 2>& out_contact) {
  const size_t n = static_cast<size_t>(sk.size());
  // Global rotations first (kept in local_rotations temporarily), then convert to local, children before parents.
  Vec3 hips_p;
  Quat q;
  out.local_rotations[0] = Quat::Identity();
  out.local_translations[0] = Vec3::Zero();
  for (int j = 1; j <= kBodyJoints; ++j) {
    Vec3 p;
    decode_joint(j, in, c, p, q);
    out.local_rotations[static_cast<size_t>(j)] = q;
    if (j == kHips) hips_p = p;
  }
  for (size_t j = n - 1; j >= 1; --j) {
    const auto parent = static_cast<size_t>(sk.parents[j]);
    out.local_rotations[j] = (out.local_rotations[parent].conjugate() * out.local_rotations[j]).normalized();
    out.local_translations[j] = sk.offsets[j];
  }
  out.local_translations[kHips] = hips_p;  // joint_Root is identity at the origin
  out_contact[0] = in[kContactOffset] > 0.5f;
  out_contact[1] = in[kContactOffset + 1] > 0.5f;
}

std::array<bool, 2> contact_labels(const GlobalPose& prev, const GlobalPose& cur, double dt_s) {
  std::array<bool, 2> out{};
  const int toes[2] = {kToesL, kToesR};
  for (int s = 0; s < 2; ++s) {
    const Vec3& a = prev.positions[static_cast<size_t>(toes[s])];
    const Vec3& b = cur.positions[static_cast<size_t>(toes[s])];
    const double speed = std::hypot(b.x() - a.x(), b.z() - a.z()) / dt_s;
    out[static_cast<size_t>(s)] = b.y() < kContactHeightM && speed < kContactSpeedMS;
  }
  return out;
}

std::array<int, kPerJoint> tracker_entries(Role role) {
  std::array<int, kPerJoint> idx{};
  const int base = joint_offset(tracker_joint(role));
  for (int k = 0; k < kPerJoint; ++k) idx[static_cast<size_t>(k)] = base + k;
  return idx;
}

}  // namespace bodyd::features
