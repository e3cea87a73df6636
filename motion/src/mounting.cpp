#include "bodyd/motion/mounting.h"

#include "bodyd/motion/skeleton.h"
#include "bodyd/paths/data_files.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

namespace bodyd {

RigidTransform compose(const RigidTransform& T_a_b, const RigidTransform& T_b_c) {
  return {T_a_b.position_m + T_a_b.rotation * T_b_c.position_m, (T_a_b.rotation * T_b_c.rotation).normalized()};
}

RigidTransform inverse(const RigidTransform& T_a_b) {
  const Quat q = T_a_b.rotation.conjugate();
  return {-(q * T_a_b.position_m), q};
}

RigidTransform pose_of(const TrackerSample& s) { return {s.position_m, s.rotation}; }

TrackerSample device_to_joint(const TrackerSample& s, const RigidTransform& T_device_joint) {
  if (s.frame != PoseFrame::Device || !s.valid) return s;
  TrackerSample out = s;
  const RigidTransform T_world_joint = compose(pose_of(s), T_device_joint);
  out.position_m = T_world_joint.position_m;
  out.rotation = T_world_joint.rotation;
  out.frame = PoseFrame::Joint;
  return out;
}

TrackerSample joint_to_device(const TrackerSample& s, const RigidTransform& T_device_joint) {
  if (s.frame != PoseFrame::Joint || !s.valid) return s;
  TrackerSample out = s;
  const RigidTransform T_world_device = compose(pose_of(s), inverse(T_device_joint));
  out.position_m = T_world_device.position_m;
  out.rotation = T_world_device.rotation;
  out.frame = PoseFrame::Device;
  return out;
}

const Quat& xr_from_facing() {
  static const Quat q(Eigen::AngleAxisd(M_PI, Vec3::UnitY()));
  return q;
}

Quat facing_from_device(const Quat& R_world_device) {
  const Vec3 sight = R_world_device * Vec3(0.0, 0.0, -1.0);
  return quat_from_yaw(std::atan2(sight.x(), sight.z()));
}

namespace {

// Sign-aligned running mean of unit quaternions (a good mean when they are close together).
struct QuatMean {
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  bool any = false;
  Eigen::Vector4d first;
  void add(const Quat& q) {
    Eigen::Vector4d v = q.coeffs();
    if (!any) {
      first = v;
      any = true;
    }
    if (v.dot(first) < 0.0) v = -v;
    sum += v;
  }
  [[nodiscard]] Quat mean() const {
    Quat q;
    q.coeffs() = sum.normalized();
    return q;
  }
};

double deg(double rad) { return rad * 180.0 / M_PI; }

// The facing rotation (facing frame -> world) of a body from its hips and shoulders.
Quat body_facing(const GlobalPose& g, int ul, int ur, int al, int ar) {
  Vec3 left = (g.positions[static_cast<size_t>(ul)] - g.positions[static_cast<size_t>(ur)]) +
              (g.positions[static_cast<size_t>(al)] - g.positions[static_cast<size_t>(ar)]);
  left.y() = 0.0;
  left.normalize();
  const Vec3 up = Vec3::UnitY();
  const Vec3 forward = left.cross(up);
  Mat3 R;
  R.col(0) = left;
  R.col(1) = up;
  R.col(2) = forward;
  return Quat(R).normalized();
}

}  // namespace

Quat mean_rotation(std::span<const Quat> rotations) {
  if (rotations.empty()) return Quat::Identity();
  QuatMean m;
  for (const Quat& q : rotations) m.add(q);
  return m.mean();
}

BodyReference measure_body_reference(std::span<const Motion> clips, std::string measured_on) {
  // A "relaxed still standing" frame: the head, both wrists and the hips each move less than
  // 0.15 m/s (over +-0.1 s), the trunk is upright (hips -> neck within 15 degrees of +Y), and
  // each arm hangs (shoulder -> wrist within 25 degrees of -Y).
  constexpr double kMaxSpeed = 0.15, kTrunkDeg = 15.0, kArmDeg = 25.0;
  constexpr int kHalf = 3;  // frames either side for the speed
  struct Sample {
    Quat head, left, right;
    double ahead_m, ratio;
    int clip;
  };
  std::vector<Sample> samples;
  int clips_used = 0;
  for (const Motion& m : clips) {
    const Skeleton& sk = m.skeleton;
    const int head = sk.find("Head"), hl = sk.find("Hand_L"), hr = sk.find("Hand_R"), hips = sk.find("Hips"),
              neck = sk.find("Neck"), ul = sk.find("UpperLeg_L"), ur = sk.find("UpperLeg_R"), al = sk.find("UpperArm_L"),
              ar = sk.find("UpperArm_R");
    if (std::min({head, hl, hr, hips, neck, ul, ur, al, ar}) < 0 || m.frame_count() < 2 * kHalf + 1) continue;
    std::vector<GlobalPose> g(static_cast<size_t>(m.frame_count()));
    for (int f = 0; f < m.frame_count(); ++f) forward_kinematics(sk, m.frames[static_cast<size_t>(f)], g[static_cast<size_t>(f)]);
    const double span_s = 2.0 * kHalf * m.frame_time_s;
    bool used = false;
    for (int f = kHalf; f + kHalf < m.frame_count(); ++f) {
      const GlobalPose& a = g[static_cast<size_t>(f - kHalf)];
      const GlobalPose& b = g[static_cast<size_t>(f + kHalf)];
      const GlobalPose& c = g[static_cast<size_t>(f)];
      bool still = true;
      for (int j : {head, hl, hr, hips})
        still &= (b.positions[static_cast<size_t>(j)] - a.positions[static_cast<size_t>(j)]).norm() / span_s < kMaxSpeed;
      if (!still) continue;
      const auto P = [&](int j) { return c.positions[static_cast<size_t>(j)]; };
      const auto angle_to = [](const Vec3& v, const Vec3& dir) {
        return deg(std::acos(std::clamp(v.normalized().dot(dir), -1.0, 1.0)));
      };
      if (angle_to(P(neck) - P(hips), Vec3::UnitY()) > kTrunkDeg) continue;
      if (angle_to(P(hl) - P(al), -Vec3::UnitY()) > kArmDeg || angle_to(P(hr) - P(ar), -Vec3::UnitY()) > kArmDeg) continue;
      const Quat F = body_facing(c, ul, ur, al, ar);
      const Quat Fi = F.conjugate();
      const Vec3 mid = 0.5 * (P(hl) + P(hr));
      const Vec3 d = Fi * (P(head) - mid);
      if (mid.y() <= 0.1) continue;
      samples.push_back({(Fi * c.rotations[static_cast<size_t>(head)]).normalized(),
                         (Fi * c.rotations[static_cast<size_t>(hl)]).normalized(),
                         (Fi * c.rotations[static_cast<size_t>(hr)]).normalized(), d.z(), P(head).y() / mid.y(), clips_used});
      used = true;
    }
    clips_used += used ? 1 : 0;
  }
  if (samples.empty())
    throw BodyReferenceError("", "no relaxed still standing frame in the clips (standing still, upright, arms hanging)",
                             "measure the reference on the training split");
  // Each clip counts once (a long still stretch of one take must not outweigh the others): the
  // per-clip means, then their mean over the clips within kOutlierDeg of a first mean (a take
  // that looks up or turns its wrists is not the reference pose). Spreads are over clips.
  constexpr double kOutlierDeg = 25.0;
  std::vector<Sample> per_clip;
  for (std::size_t i = 0; i < samples.size();) {
    std::size_t j = i;
    QuatMean h, l, rr;
    double ahead = 0.0, ratio = 0.0;
    for (; j < samples.size() && samples[j].clip == samples[i].clip; ++j) {
      h.add(samples[j].head);
      l.add(samples[j].left);
      rr.add(samples[j].right);
      ahead += samples[j].ahead_m;
      ratio += samples[j].ratio;
    }
    const double n = static_cast<double>(j - i);
    per_clip.push_back({h.mean(), l.mean(), rr.mean(), ahead / n, ratio / n, samples[i].clip});
    i = j;
  }
  const auto mean_of = [](const std::vector<Sample>& v, const std::vector<bool>& keep, Quat Sample::*field) {
    QuatMean m;
    for (std::size_t i = 0; i < v.size(); ++i)
      if (keep[i]) m.add(v[i].*field);
    return m.mean();
  };
  std::vector<bool> keep(per_clip.size(), true);
  const Quat head0 = mean_of(per_clip, keep, &Sample::head), left0 = mean_of(per_clip, keep, &Sample::left),
             right0 = mean_of(per_clip, keep, &Sample::right);
  for (std::size_t i = 0; i < per_clip.size(); ++i)
    keep[i] = deg(geodesic_angle(per_clip[i].head, head0)) <= kOutlierDeg &&
              deg(geodesic_angle(per_clip[i].left, left0)) <= kOutlierDeg &&
              deg(geodesic_angle(per_clip[i].right, right0)) <= kOutlierDeg;
  if (std::count(keep.begin(), keep.end(), true) == 0)
    throw BodyReferenceError("", "the relaxed still standing frames disagree (no clip within 25 degrees of their mean)",
                             "measure the reference on more clips, e.g. the training split");
  BodyReference r;
  r.head_in_facing = mean_of(per_clip, keep, &Sample::head);
  r.hand_in_facing = {mean_of(per_clip, keep, &Sample::left), mean_of(per_clip, keep, &Sample::right)};
  double n = 0.0, ahead = 0.0, ratio = 0.0;
  long frames = 0;
  for (std::size_t i = 0; i < per_clip.size(); ++i) {
    if (!keep[i]) continue;
    n += 1.0;
    ahead += per_clip[i].ahead_m;
    ratio += per_clip[i].ratio;
    for (const Sample& s : samples) frames += s.clip == per_clip[i].clip ? 1 : 0;
  }
  r.head_ahead_of_wrists_m = ahead / n;
  r.head_over_wrist_height = ratio / n;
  double pitch2 = 0.0, roll2 = 0.0, l2 = 0.0, r2 = 0.0, ahead2 = 0.0, ratio2 = 0.0;
  for (std::size_t i = 0; i < per_clip.size(); ++i) {
    if (!keep[i]) continue;
    const Sample& s = per_clip[i];
    // Deviation in the facing frame: pitch about its +X (left), roll about its +Z (forward).
    const Vec3 v = axis_angle_from_quat((s.head * r.head_in_facing.conjugate()).normalized());
    pitch2 += v.x() * v.x();
    roll2 += v.z() * v.z();
    l2 += std::pow(geodesic_angle(s.left, r.hand_in_facing[0]), 2);
    r2 += std::pow(geodesic_angle(s.right, r.hand_in_facing[1]), 2);
    ahead2 += std::pow(s.ahead_m - r.head_ahead_of_wrists_m, 2);
    ratio2 += std::pow(s.ratio - r.head_over_wrist_height, 2);
  }
  r.head_pitch_sd_deg = deg(std::sqrt(pitch2 / n));
  r.head_roll_sd_deg = deg(std::sqrt(roll2 / n));
  r.hand_sd_deg = {deg(std::sqrt(l2 / n)), deg(std::sqrt(r2 / n))};
  r.head_ahead_sd_m = std::sqrt(ahead2 / n);
  r.head_over_wrist_height_sd = std::sqrt(ratio2 / n);
  r.clips = static_cast<int>(n);
  r.frames = frames;
  r.measured_on = std::move(measured_on);
  return r;
}

namespace {

nlohmann::json quat_json(const Quat& q) { return {q.x(), q.y(), q.z(), q.w()}; }

}  // namespace

std::string body_reference_json(const BodyReference& r) {
  nlohmann::ordered_json j;
  j["format"] = "bodyd-body-reference v1";
  j["about"] = "Measured by bodyd-bvh reference (docs/conventions.md, \"Device frames\"): the facing frame is +Z forward, "
               "+Y up, +X the body's left; quaternions x, y, z, w.";
  j["measured_on"] = r.measured_on;
  j["clips"] = r.clips;
  j["frames"] = r.frames;
  j["head_in_facing_xyzw"] = quat_json(r.head_in_facing);
  j["head_pitch_sd_deg"] = r.head_pitch_sd_deg;
  j["head_roll_sd_deg"] = r.head_roll_sd_deg;
  j["left_hand_in_facing_xyzw"] = quat_json(r.hand_in_facing[0]);
  j["right_hand_in_facing_xyzw"] = quat_json(r.hand_in_facing[1]);
  j["hand_sd_deg"] = {r.hand_sd_deg[0], r.hand_sd_deg[1]};
  j["head_ahead_of_wrists_m"] = r.head_ahead_of_wrists_m;
  j["head_ahead_sd_m"] = r.head_ahead_sd_m;
  j["head_over_wrist_height"] = r.head_over_wrist_height;
  j["head_over_wrist_height_sd"] = r.head_over_wrist_height_sd;
  return j.dump(2) + "\n";
}

BodyReference parse_body_reference(std::string_view text, const std::string& source) {
  constexpr const char* kRegenerate =
      "regenerate it with bodyd-bvh --reference (docs/conventions.md, \"Device frames\")";
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw BodyReferenceError(source, fmt::format("not JSON: {}", e.what()), kRegenerate);
  }
  const auto fail = [&](const std::string& what) -> BodyReferenceError {
    return BodyReferenceError(source, what, kRegenerate);
  };
  if (!j.is_object() || j.value("format", "") != "bodyd-body-reference v1")
    throw fail("\"format\" is not \"bodyd-body-reference v1\"");
  const auto number = [&](const char* key, double lo, double hi) {
    if (!j.contains(key) || !j[key].is_number()) throw fail(fmt::format("\"{}\" is missing or not a number", key));
    const double v = j[key].get<double>();
    if (!std::isfinite(v) || v < lo || v > hi) throw fail(fmt::format("\"{}\" is {}, outside {} .. {}", key, v, lo, hi));
    return v;
  };
  const auto quat = [&](const char* key) {
    if (!j.contains(key) || !j[key].is_array() || j[key].size() != 4)
      throw fail(fmt::format("\"{}\" is not an array of 4 numbers (x, y, z, w)", key));
    double c[4];
    for (int i = 0; i < 4; ++i) {
      if (!j[key][static_cast<size_t>(i)].is_number()) throw fail(fmt::format("\"{}\"[{}] is not a number", key, i));
      c[i] = j[key][static_cast<size_t>(i)].get<double>();
      if (!std::isfinite(c[i])) throw fail(fmt::format("\"{}\"[{}] is not finite", key, i));
    }
    const Quat q(c[3], c[0], c[1], c[2]);
    if (std::abs(q.norm() - 1.0) > 1e-3) throw fail(fmt::format("\"{}\" is not a unit quaternion", key));
    return q.normalized();
  };
  BodyReference r;
  r.head_in_facing = quat("head_in_facing_xyzw");
  r.hand_in_facing = {quat("left_hand_in_facing_xyzw"), quat("right_hand_in_facing_xyzw")};
  r.head_pitch_sd_deg = number("head_pitch_sd_deg", 0.0, 90.0);
  r.head_roll_sd_deg = number("head_roll_sd_deg", 0.0, 90.0);
  if (!j.contains("hand_sd_deg") || !j["hand_sd_deg"].is_array() || j["hand_sd_deg"].size() != 2 ||
      !j["hand_sd_deg"][0].is_number() || !j["hand_sd_deg"][1].is_number())
    throw fail("\"hand_sd_deg\" is not an array of 2 numbers");
  r.hand_sd_deg = {j["hand_sd_deg"][0].get<double>(), j["hand_sd_deg"][1].get<double>()};
  r.head_ahead_of_wrists_m = number("head_ahead_of_wrists_m", -0.5, 0.5);
  r.head_ahead_sd_m = number("head_ahead_sd_m", 0.0, 0.5);
  r.head_over_wrist_height = number("head_over_wrist_height", 1.0, 4.0);
  r.head_over_wrist_height_sd = number("head_over_wrist_height_sd", 0.0, 1.0);
  r.clips = static_cast<int>(number("clips", 1, 1e6));
  r.frames = static_cast<long>(number("frames", 1, 1e9));
  r.measured_on = j.value("measured_on", "");
  return r;
}

BodyReference read_body_reference(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in)
    throw BodyReferenceError(path.string(), "cannot open the body reference",
                             "check that bodyd is installed completely, or give a readable file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_body_reference(ss.str(), path.string());
}

std::filesystem::path find_body_reference(const std::string& path) {
  if (!path.empty()) return path;
  const paths::DataFile f = paths::find_data_file(kBodyReferenceFile);
  if (!f.found)
    throw BodyReferenceError(
        "",
        fmt::format("the body reference {} is not installed (looked in {})", kBodyReferenceFile, paths::tried_text(f)),
        "reinstall bodyd, or make one with bodyd-bvh --reference");
  return f.path;
}

std::string transform_text(const RigidTransform& T) {
  return fmt::format("position_m {},{},{} rotation_xyzw {},{},{},{}", T.position_m.x(), T.position_m.y(),
                     T.position_m.z(), T.rotation.x(), T.rotation.y(), T.rotation.z(), T.rotation.w());
}

std::string mounting_text(const Mounting& m) {
  std::string out;
  for (Role r : kRoles) {
    const RigidTransform& T = m.T_device_joint[static_cast<size_t>(r)];
    // A body tracker's only when it has one (measured, or a simulated strap).
    if (!is_xr_role(r) && T.position_m.isZero(0.0) && T.rotation.coeffs().isApprox(Quat::Identity().coeffs(), 0.0)) continue;
    out += fmt::format("{}{} {}", out.empty() ? "" : "; ", role_name(r), transform_text(T));
  }
  return out;
}

Mounting default_mounting(const BodyReference& r) {
  Mounting m;
  const Quat& X = xr_from_facing();
  // Head: the joint is below and behind the eyes; in the device's axes (+Y up, -Z ahead).
  m.T_device_joint[static_cast<int>(Role::Head)] = {Vec3(0.0, -kEyeAboveHeadJointM, kEyeAheadOfHeadJointM),
                                                    (X * r.head_in_facing).normalized()};
  // Hands: a hanging hand with its controller pointing ahead has grip axes +X to the user's right,
  // +Y up, +Z back; the wrist is above the grip point and towards the back of the hand, which is
  // the user's left (-X) for the left hand and the right (+X) for the right hand.
  m.T_device_joint[static_cast<int>(Role::LeftHand)] = {Vec3(-kGripToWristAcrossPalmM, kGripToWristAlongHandM, 0.0),
                                                        (X * r.hand_in_facing[0]).normalized()};
  m.T_device_joint[static_cast<int>(Role::RightHand)] = {Vec3(kGripToWristAcrossPalmM, kGripToWristAlongHandM, 0.0),
                                                         (X * r.hand_in_facing[1]).normalized()};
  return m;
}

std::array<RigidTransform, kRoleCount> calibration_pose_joints(const BodyReference& ref, const Vec3& head_position_m,
                                                               double heading_rad, double half_width_m) {
  const Quat F = quat_from_yaw(heading_rad);
  const double wrist_y = head_position_m.y() / ref.head_over_wrist_height;
  const Vec3 floor_head(head_position_m.x(), 0.0, head_position_m.z());
  std::array<RigidTransform, kRoleCount> j;
  j[0] = {head_position_m, (F * ref.head_in_facing).normalized()};
  // Facing frame: +X is the body's left; the head is head_ahead_of_wrists_m ahead of the wrists.
  j[1] = {floor_head + F * Vec3(half_width_m, wrist_y, -ref.head_ahead_of_wrists_m), (F * ref.hand_in_facing[0]).normalized()};
  j[2] = {floor_head + F * Vec3(-half_width_m, wrist_y, -ref.head_ahead_of_wrists_m), (F * ref.hand_in_facing[1]).normalized()};
  return j;
}

MountingDifference mounting_difference(const RigidTransform& a, const RigidTransform& b) {
  return {deg(geodesic_angle(a.rotation, b.rotation)), 100.0 * (a.position_m - b.position_m).norm()};
}

}  // namespace bodyd
