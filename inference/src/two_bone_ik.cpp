#include "bodyd/inference/two_bone_ik.h"

#include <algorithm>
#include <cmath>

namespace bodyd {

std::optional<TwoBoneChain> find_two_bone_chain(const Skeleton& skeleton, std::string_view upper,
                                                std::string_view lower, std::string_view end) {
  TwoBoneChain c{skeleton.find(upper), skeleton.find(lower), skeleton.find(end)};
  if (c.upper < 0 || c.lower < 0 || c.end < 0) return std::nullopt;
  if (skeleton.parents[static_cast<size_t>(c.lower)] != c.upper ||
      skeleton.parents[static_cast<size_t>(c.end)] != c.lower)
    return std::nullopt;
  return c;
}

namespace {

// A unit vector perpendicular to `d` (unit), preferring the component of `hint` across d.
// Returns false when hint is (nearly) along d.
bool perpendicular_toward(const Vec3& d, const Vec3& hint, Vec3& out) {
  const Vec3 across = hint - hint.dot(d) * d;
  const double n = across.norm();
  if (n < 1e-9 * std::max(1.0, hint.norm())) return false;
  out = across / n;
  return true;
}

// Hinge mode (see TwoBoneTarget::keep_hinge). The current bend axis in the upper bone's frame,
// h = bone x forearm, is mapped onto the new bend normal; the upper bone's global rotation is the
// one taking the frame (bone, h, bone x h) to (upper, normal, upper x normal), and the lower joint
// turns about h until the forearm points along `lower`. Both forearm directions are normal to h,
// so the rotation about h reaches the target exactly. False when the current chain is straight.
bool solve_hinge(const Pose& pose, const TwoBoneChain& chain, const Vec3& upper, const Vec3& lower,
                 const Vec3& bend_normal, Quat& g_upper, Quat& g_lower) {
  const Quat& l_lower = pose.local_rotations[static_cast<size_t>(chain.lower)];
  const Vec3 bone = pose.local_translations[static_cast<size_t>(chain.lower)].normalized();
  const Vec3 forearm = (l_lower * pose.local_translations[static_cast<size_t>(chain.end)]).normalized();
  Vec3 h = bone.cross(forearm);
  if (h.norm() < std::sin(M_PI / 180.0)) return false;
  h.normalize();
  const Vec3 u = upper.normalized(), v = lower.normalized(), nrm = bend_normal.normalized();
  Mat3 from, to;
  from << bone, h, bone.cross(h);
  to << u, nrm, u.cross(nrm);
  g_upper = Quat(Mat3(to * from.transpose())).normalized();
  const Vec3 w = g_upper.conjugate() * v;  // target forearm direction in the upper bone's frame
  const double phi = std::atan2(forearm.cross(w).dot(h), forearm.dot(w));
  g_lower = (g_upper * Quat(Eigen::AngleAxisd(phi, h)) * l_lower).normalized();
  return true;
}

}  // namespace

TwoBoneResult solve_two_bone_ik(const Skeleton& skeleton, const TwoBoneChain& chain, const TwoBoneTarget& target,
                                Pose& pose, GlobalPose& global) {
  const auto u = static_cast<size_t>(chain.upper), l = static_cast<size_t>(chain.lower),
             e = static_cast<size_t>(chain.end);
  const Vec3 a = global.positions[u];  // shoulder end of the upper arm
  const Vec3 b = global.positions[l];  // elbow
  const Vec3 c = global.positions[e];  // hand
  const double len_ab = (b - a).norm(), len_bc = (c - b).norm();

  TwoBoneResult result;
  if (len_ab < 1e-9 || len_bc < 1e-9) {
    result.error_m = (c - target.position_m).norm();
    return result;
  }

  // Direction from the shoulder to the target; for a target on the shoulder keep the
  // current shoulder-to-hand direction (or the upper arm's).
  Vec3 to_target = target.position_m - a;
  const double dist = to_target.norm();
  Vec3 d;
  if (dist > 1e-12)
    d = to_target / dist;
  else if ((c - a).norm() > 1e-12)
    d = (c - a).normalized();
  else
    d = (b - a) / len_ab;

  const double min_reach = std::abs(len_ab - len_bc), max_reach = len_ab + len_bc;
  double reach = std::clamp(dist, min_reach, max_reach);
  result.reachable = dist >= min_reach && dist <= max_reach;
  // Soft reach (TwoBoneTarget::soft_zone_m): a zone wider than the chain's range of reach is
  // narrowed to it, so the soft curve stays above min_reach.
  const double zone = std::min(std::isfinite(target.soft_zone_m) ? std::max(0.0, target.soft_zone_m) : 0.0,
                               max_reach - min_reach);
  if (zone > 0.0 && dist > max_reach - zone) {
    reach = max_reach - zone * std::exp(-(dist - max_reach + zone) / zone);
    result.reachable = false;
  }

  // The plane of the elbow: the pole's direction across d; fall back to the current elbow's,
  // then the current hand-to-elbow bend, then any direction across d.
  Vec3 n;
  const Vec3 pole = target.pole_m ? *target.pole_m : b;
  if (!perpendicular_toward(d, pole - a, n) && !perpendicular_toward(d, b - a, n) &&
      !perpendicular_toward(d, b - 0.5 * (a + c), n)) {
    const Vec3 axis = std::abs(d.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
    n = d.cross(axis).normalized();
  }

  // Law of cosines for the angle at the shoulder between d and the upper arm.
  const double cos_a =
      std::clamp((len_ab * len_ab + reach * reach - len_bc * len_bc) / (2.0 * len_ab * reach), -1.0, 1.0);
  const double sin_a = std::sqrt(std::max(0.0, 1.0 - cos_a * cos_a));
  const Vec3 elbow = a + len_ab * (cos_a * d + sin_a * n);
  const Vec3 hand = a + reach * d;

  Quat g_upper, g_lower;
  if (!(target.keep_hinge && solve_hinge(pose, chain, elbow - a, hand - elbow, n.cross(d), g_upper, g_lower))) {
    // Smallest rotations: the upper arm onto the new elbow, then the lower arm onto the hand.
    const Quat r1 = Quat::FromTwoVectors(b - a, elbow - a).normalized();
    const Vec3 c1 = a + r1 * (c - a);
    const Quat r2 = Quat::FromTwoVectors(c1 - elbow, hand - elbow).normalized();
    g_upper = (r1 * global.rotations[u]).normalized();
    g_lower = (r2 * r1 * global.rotations[l]).normalized();
  }
  const int parent = skeleton.parents[u];
  const Quat g_parent = parent >= 0 ? global.rotations[static_cast<size_t>(parent)] : Quat::Identity();
  pose.local_rotations[u] = (g_parent.conjugate() * g_upper).normalized();
  pose.local_rotations[l] = (g_upper.conjugate() * g_lower).normalized();
  if (target.rotation) pose.local_rotations[e] = (g_lower.conjugate() * target.rotation->normalized()).normalized();

  forward_kinematics(skeleton, pose, global);
  result.error_m = (global.positions[e] - target.position_m).norm();
  return result;
}

}  // namespace bodyd
