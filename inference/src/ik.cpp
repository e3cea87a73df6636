#include "bodyd/inference/ik.h"

#include "bodyd/base/user_error.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <string_view>

namespace bodyd {

namespace {

struct JointRotation {
  std::string_view name;
  double x, y, z, w;  // local rotation, (x, y, z, w) order
};

// Local rotations of frame 5 of dataset-1/dataset-1_call_normal_002.bvh (Bandai Namco Research
// Motion Dataset, CC BY-NC 4.0), read with read_bvh and printed to 7 decimals. See ik.h.
constexpr JointRotation kStandingFrame[] = {
    {"joint_Root", 0.0000000, 0.0000000, 0.0000000, 1.0000000},
    {"Hips", -0.0677474, -0.0930006, 0.7021313, 0.7026897},
    {"Spine", 0.7183738, 0.0285390, -0.0025841, 0.6950669},
    {"Chest", 0.0165627, -0.0018988, -0.0138640, 0.9997649},
    {"Neck", 0.0360956, -0.0027110, -0.0279282, 0.9989543},
    {"Head", 0.0444995, -0.0074565, -0.0662366, 0.9967833},
    {"Shoulder_L", -0.4555664, -0.5172308, -0.5400952, 0.4829377},
    {"UpperArm_L", -0.1998775, 0.2176275, -0.5456862, 0.7841644},
    {"LowerArm_L", 0.0000000, -0.1862394, -0.0000003, 0.9825044},
    {"Hand_L", 0.3839337, 0.0167449, 0.1022222, 0.9175321},
    {"Shoulder_R", 0.5197839, -0.4368093, 0.4778612, 0.5573787},
    {"UpperArm_R", -0.0761104, 0.1542028, -0.5403076, 0.8237089},
    {"LowerArm_R", -0.0000004, -0.2204795, 0.0000117, 0.9753916},
    {"Hand_R", 0.2953242, 0.0436639, 0.0736708, 0.9515512},
    {"UpperLeg_L", 0.0203179, -0.0378074, 0.9990637, 0.0054412},
    {"LowerLeg_L", -0.0000000, 0.0217643, 0.0000000, 0.9997631},
    {"Foot_L", -0.0780223, -0.4496444, 0.0402820, 0.8888812},
    {"Toes_L", -0.0020354, -0.1484510, -0.0007254, 0.9889174},
    {"UpperLeg_R", -0.9923697, -0.0282307, -0.0285501, 0.1165777},
    {"LowerLeg_R", -0.0000000, 0.0129904, 0.0000000, 0.9999156},
    {"Foot_R", -0.2805547, -0.4501805, 0.1264618, 0.8382327},
    {"Toes_R", 0.0066382, -0.1573309, 0.0017022, 0.9875222},
};

constexpr const char* kUseTheBodydSkeleton =
    "use motion data on the bodyd skeleton (docs/conventions.md, \"Skeleton and joint sets\")";
// Height of the lower Toes joint in that frame (metres).
constexpr double kStandingToesHeightM = 0.045;

int require(const Skeleton& skeleton, std::string_view name, std::string_view what) {
  const int j = skeleton.find(name);
  if (j < 0)
    throw UserError(std::string(what), "the skeleton has no joint '" + std::string(name) + "'",
                    "expected the joints of the bundled motion data (docs/evaluation.md)");
  return j;
}

}  // namespace

StandingReference standing_reference(const Skeleton& skeleton) {
  if (const std::string err = skeleton.validate(); !err.empty())
    throw UserError("standing reference", "invalid skeleton: " + err, kUseTheBodydSkeleton);
  StandingReference ref;
  ref.pose = rest_pose(skeleton);
  for (int j = 0; j < skeleton.size(); ++j) {
    const std::string& name = skeleton.names[static_cast<size_t>(j)];
    const JointRotation* found = nullptr;
    for (const JointRotation& r : kStandingFrame)
      if (r.name == name) found = &r;
    if (found == nullptr)
      throw UserError("standing reference",
                      "joint '" + name + "' is not a joint of the bundled motion data's skeleton; the reference "
                      "standing pose only knows that skeleton",
                      kUseTheBodydSkeleton);
    ref.pose.local_rotations[static_cast<size_t>(j)] = Quat(found->w, found->x, found->y, found->z).normalized();
  }
  const auto hips = static_cast<size_t>(require(skeleton, "Hips", "standing reference"));
  const auto head = static_cast<size_t>(require(skeleton, "Head", "standing reference"));
  const auto leg_l = static_cast<size_t>(require(skeleton, "UpperLeg_L", "standing reference"));
  const auto leg_r = static_cast<size_t>(require(skeleton, "UpperLeg_R", "standing reference"));
  const auto toes_l = static_cast<size_t>(require(skeleton, "Toes_L", "standing reference"));
  const auto toes_r = static_cast<size_t>(require(skeleton, "Toes_R", "standing reference"));
  if (skeleton.parents[hips] > 0)
    throw UserError("standing reference", "'Hips' must be the root or a child of the root", kUseTheBodydSkeleton);
  // The root (joint_Root) stays at the origin; the hips carry the world position.
  if (hips != 0) {
    ref.pose.local_rotations[0] = Quat::Identity();
    ref.pose.local_translations[0] = Vec3::Zero();
  }
  ref.pose.local_translations[hips] = Vec3::Zero();

  // Face +Z: the forward direction is across the hip line (left hip minus right hip) on the floor.
  forward_kinematics(skeleton, ref.pose, ref.global);
  const Vec3 left = ref.global.positions[leg_l] - ref.global.positions[leg_r];
  const Vec3 forward = left.cross(Vec3::UnitY());
  const double yaw = std::atan2(forward.x(), forward.z());
  ref.pose.local_rotations[hips] = (quat_from_yaw(-yaw) * ref.pose.local_rotations[hips]).normalized();

  forward_kinematics(skeleton, ref.pose, ref.global);
  const double toes_y = std::min(ref.global.positions[toes_l].y(), ref.global.positions[toes_r].y());
  ref.pose.local_translations[hips] = Vec3(0.0, kStandingToesHeightM - toes_y, 0.0);
  forward_kinematics(skeleton, ref.pose, ref.global);

  ref.head_height_m = ref.global.positions[head].y();
  const Quat head_inv = ref.global.rotations[head].conjugate();
  ref.head_forward_local = (head_inv * Vec3::UnitZ()).normalized();
  ref.head_up_local = (head_inv * Vec3::UnitY()).normalized();
  return ref;
}

double standing_head_height_m(const Skeleton& skeleton) { return standing_reference(skeleton).head_height_m; }

double head_yaw_rad(const Quat& head_rotation, const StandingReference& reference) {
  const Vec3 f = head_rotation * reference.head_forward_local;
  const Vec3 u = head_rotation * reference.head_up_local;
  // Pitch the face down by p: f = cos p F - sin p Y, u = sin p F + cos p Y, so
  // f_h - f_y u_h = (cos p + sin^2 p) F, which points along F for every p in [-90, 90] degrees.
  const double hx = f.x() - f.y() * u.x();
  const double hz = f.z() - f.y() * u.z();
  if (hx * hx + hz * hz < 1e-12) return 0.0;  // head rolled onto its side and facing up: no heading
  return std::atan2(hx, hz);
}

IkReconstructor::IkReconstructor(const Skeleton& skeleton, const IkOptions& options)
    : model_skeleton_(skeleton),
      user_skeleton_(skeleton),
      reference_(standing_reference(skeleton)),
      history_(options.history) {
  hips_ = require(skeleton, "Hips", "ik");
  head_ = require(skeleton, "Head", "ik");
  for (int j = skeleton.parents[static_cast<size_t>(head_)]; j != hips_; j = skeleton.parents[static_cast<size_t>(j)]) {
    if (j < 0) throw UserError("", "'Head' is not a descendant of 'Hips'", kUseTheBodydSkeleton);
    spine_.insert(spine_.begin(), j);
  }
  const char* names[2][3] = {{"UpperArm_L", "LowerArm_L", "Hand_L"}, {"UpperArm_R", "LowerArm_R", "Hand_R"}};
  for (int side = 0; side < 2; ++side) {
    const auto chain = find_two_bone_chain(skeleton, names[side][0], names[side][1], names[side][2]);
    if (!chain)
      throw UserError("",
                      std::string("the skeleton has no arm chain ") + names[side][0] + " -> " + names[side][1] +
                          " -> " + names[side][2],
                      kUseTheBodydSkeleton);
    arms_[static_cast<size_t>(side)] = *chain;
  }
  head_height_m_ = reference_.head_height_m;
  work_pose_ = reference_.pose;
  work_global_ = reference_.global;
}

void IkReconstructor::reset() {
  history_.clear();
  have_head_ = false;
}

void IkReconstructor::set_head_height_m(double height_m) {
  head_height_m_ = height_m > 0.0 && std::isfinite(height_m) ? height_m : reference_.head_height_m;
  const double k = head_height_m_ / reference_.head_height_m;
  for (size_t j = 0; j < model_skeleton_.offsets.size(); ++j) {
    user_skeleton_.offsets[j] = model_skeleton_.offsets[j] * k;
    if (model_skeleton_.end_sites[j]) user_skeleton_.end_sites[j] = *model_skeleton_.end_sites[j] * k;
  }
}

bool IkReconstructor::reconstruct(std::int64_t t_ns, BodyPose& out) {
  // Tracker positions into the model's scale, and the output back to the user's.
  const double to_model = reference_.head_height_m / head_height_m_;

  TrackerSample head;
  const bool head_valid = history_.query(Role::Head, t_ns, head);
  if (head_valid) {
    last_head_ = head;
    last_head_.position_m *= to_model;
    have_head_ = true;
  } else if (const TrackerSample* held = history_.newest_valid_at_or_before(Role::Head, t_ns)) {
    if (!have_head_ || held->t_ns > last_head_.t_ns) {
      last_head_ = *held;
      last_head_.position_m *= to_model;
      have_head_ = true;
    }
  }
  if (!have_head_) return false;

  const StandingReference& ref = reference_;
  const Quat heading = quat_from_yaw(head_yaw_rad(last_head_.rotation, ref));
  Pose& pose = work_pose_;
  GlobalPose& global = work_global_;
  for (size_t j = 0; j < pose.local_rotations.size(); ++j) {
    pose.local_rotations[j] = ref.pose.local_rotations[j];
    pose.local_translations[j] = ref.pose.local_translations[j];
  }
  const auto hips = static_cast<size_t>(hips_), head_j = static_cast<size_t>(head_);
  const int hips_parent = model_skeleton_.parents[hips];
  const Quat g_hips_parent =
      hips_parent >= 0 ? ref.global.rotations[static_cast<size_t>(hips_parent)] : Quat::Identity();

  // Global rotations down the spine: the heading, then a growing share of the head's tilt.
  const Quat g_hips = (heading * ref.global.rotations[hips]).normalized();
  pose.local_rotations[hips] = (g_hips_parent.conjugate() * g_hips).normalized();
  const Quat tilt = (last_head_.rotation * (heading * ref.global.rotations[head_j]).conjugate()).normalized();
  Quat g_parent = g_hips;
  const auto n_spine = static_cast<double>(spine_.size());
  for (size_t k = 0; k < spine_.size(); ++k) {
    const auto j = static_cast<size_t>(spine_[k]);
    const double share = 0.5 * static_cast<double>(k + 1) / n_spine;
    const Quat g = (slerp(Quat::Identity(), tilt, share) * heading * ref.global.rotations[j]).normalized();
    pose.local_rotations[j] = (g_parent.conjugate() * g).normalized();
    g_parent = g;
  }
  pose.local_rotations[head_j] = (g_parent.conjugate() * last_head_.rotation.normalized()).normalized();

  // Place the hips so the Head joint lands on the tracked head.
  forward_kinematics(model_skeleton_, pose, global);
  const Vec3 shift = last_head_.position_m - global.positions[head_j];
  pose.local_translations[hips] += g_hips_parent.conjugate() * shift;
  forward_kinematics(model_skeleton_, pose, global);

  std::array<bool, kRoleCount> valid{head_valid, false, false};
  for (int side = 0; side < 2; ++side) {
    const Role role = side == 0 ? Role::LeftHand : Role::RightHand;
    TrackerSample hand;
    if (!history_.query(role, t_ns, hand)) continue;
    valid[static_cast<size_t>(role)] = true;
    TwoBoneTarget target;
    target.position_m = hand.position_m * to_model;
    target.rotation = hand.rotation;
    target.keep_hinge = true;
    (void)solve_two_bone_ik(model_skeleton_, arms_[static_cast<size_t>(side)], target, pose, global);
  }

  // Back to the user's scale: every translation scales, rotations do not.
  out.t_ns = t_ns;
  out.pose.local_rotations = pose.local_rotations;
  out.pose.local_translations.resize(pose.local_translations.size());
  const double to_user = 1.0 / to_model;
  for (size_t j = 0; j < pose.local_translations.size(); ++j)
    out.pose.local_translations[j] = pose.local_translations[j] * to_user;
  forward_kinematics(user_skeleton_, out.pose, out.global);
  out.foot_contact = {true, true};
  out.tracker_valid = valid;
  return true;
}

}  // namespace bodyd
