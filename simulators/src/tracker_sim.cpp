#include "bodyd/simulators/tracker_sim.h"

#include "bodyd/base/random.h"
#include "bodyd/motion/limits.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace bodyd {
namespace {

constexpr double kMaxRateHz = 10'000.0;

// The random effects; each (role, effect) pair has its own stream so that turning one
// effect on or changing one role's rate leaves the other streams' numbers unchanged.
enum class Effect : std::uint64_t { PositionNoise = 1, RotationNoise = 2, Jitter = 3, Dropout = 4 };

// std::mt19937_64's output sequence is specified by the standard; the transforms
// below are ours (std distributions differ between standard libraries).
class Rng {
 public:
  Rng(std::uint64_t seed, Role role, Effect effect)
      : engine_(splitmix64_at(seed ^ splitmix64_at((static_cast<std::uint64_t>(role) << 8) |
                                                     static_cast<std::uint64_t>(effect), 0), 0)) {}

  double uniform01() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }  // [0, 1)
  // Box-Muller; 1 - u is in (0, 1], so the log is finite.
  double normal() {
    if (have_spare_) {
      have_spare_ = false;
      return spare_;
    }
    const double r = std::sqrt(-2.0 * std::log(1.0 - uniform01()));
    const double theta = 2.0 * M_PI * uniform01();
    spare_ = r * std::sin(theta);
    have_spare_ = true;
    return r * std::cos(theta);
  }
  double exponential(double mean) { return -mean * std::log(1.0 - uniform01()); }

 private:
  std::mt19937_64 engine_;
  double spare_ = 0.0;
  bool have_spare_ = false;
};

bool finite_in(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

}  // namespace

double SimOptions::rate_of(Role role) const {
  const double r = role_rate_hz[static_cast<size_t>(role)];
  return r > 0.0 ? r : rate_hz;
}

double SimOptions::dropout_fraction() const {
  const double x = dropout_rate_hz * dropout_mean_ms * 1e-3;
  return x / (1.0 + x);
}

// SimOptions::validate(): sim_option_keys.cpp, from the table of options.

// ---------------------------------------------------------------------------------------------

TrackerTrajectory::TrackerTrajectory(const Motion& motion) {
  const Skeleton& sk = motion.skeleton;
  if (std::string err = sk.validate(); !err.empty()) throw SimError("", "cannot simulate trackers: " + err);
  if (motion.frames.empty()) throw SimError("", "cannot simulate trackers: the clip has no frames");
  if (!finite_in(motion.frame_time_s, 1e-6, 10.0))
    throw SimError("", fmt::format("cannot simulate trackers: frame time {} s is not usable", motion.frame_time_s));
  std::array<int, kRoleCount> joint{};
  for (Role r : kRoles) {
    joint[static_cast<size_t>(r)] = sk.find(role_joint_name(r));
    if (joint[static_cast<size_t>(r)] < 0)
      throw SimError("",
                     fmt::format("cannot simulate trackers: the skeleton has no joint '{}' (tracked by role {})",
                                 role_joint_name(r), role_name(r)),
                     "use motion data on the bodyd skeleton (docs/conventions.md, \"Skeleton and joint sets\")");
  }
  frames_ = motion.frame_count();
  frame_time_s_ = motion.frame_time_s;
  duration_ns_ = std::llround(static_cast<double>(frames_ - 1) * frame_time_s_ * 1e9);
  for (auto& v : positions_m_) v.reserve(static_cast<size_t>(frames_));
  for (auto& v : rotations_) v.reserve(static_cast<size_t>(frames_));
  GlobalPose global;
  const auto nj = static_cast<size_t>(sk.size());
  for (int f = 0; f < frames_; ++f) {
    const Pose& pose = motion.frames[static_cast<size_t>(f)];
    if (pose.local_rotations.size() != nj || pose.local_translations.size() != nj)
      throw SimError("", fmt::format("cannot simulate trackers: frame {} has {} rotations and {} translations for {} "
                                     "joints",
                                     f, pose.local_rotations.size(), pose.local_translations.size(), nj));
    forward_kinematics(sk, pose, global);
    for (Role r : kRoles) {
      const auto ri = static_cast<size_t>(r);
      const auto j = static_cast<size_t>(joint[ri]);
      if (!global.positions[j].allFinite() || !global.rotations[j].coeffs().allFinite())
        throw SimError(
            "", fmt::format("cannot simulate trackers: joint '{}' is not finite in frame {}", role_joint_name(r), f));
      // A tracker log holds positions within limits::kMaxAbsPositionM; a clip whose joints lie
      // beyond (a BVH value the reader let through, or a skeleton built in code) is refused here
      // rather than written as a log no reader accepts.
      const Vec3& p = global.positions[j];
      if (!limits::position_plausible(p.x()) || !limits::position_plausible(p.y()) ||
          !limits::position_plausible(p.z()))
        throw SimError("", fmt::format("cannot simulate trackers: joint '{}' is at ({:.6g}, {:.6g}, {:.6g}) m in frame "
                                       "{}, outside the plausible range +-{} m of a tracker position",
                                       role_joint_name(r), p.x(), p.y(), p.z(), f, limits::kMaxAbsPositionM));
      positions_m_[ri].push_back(global.positions[j]);
      rotations_[ri].push_back(global.rotations[j].normalized());
    }
  }
}

TrackerSample TrackerTrajectory::pose_at(Role role, std::int64_t t_ns) const {
  const auto ri = static_cast<size_t>(role);
  TrackerSample s;
  s.t_ns = t_ns;
  s.role = role;
  s.valid = true;
  const double f = static_cast<double>(t_ns) * 1e-9 / frame_time_s_;
  const double last = static_cast<double>(frames_ - 1);
  if (!(f > 0.0)) {
    s.position_m = positions_m_[ri].front();
    s.rotation = rotations_[ri].front();
  } else if (f >= last) {
    s.position_m = positions_m_[ri].back();
    s.rotation = rotations_[ri].back();
  } else {
    const auto i = static_cast<size_t>(std::floor(f));
    const double a = f - static_cast<double>(i);
    s.position_m = (1.0 - a) * positions_m_[ri][i] + a * positions_m_[ri][i + 1];
    s.rotation = slerp(rotations_[ri][i], rotations_[ri][i + 1], a);
  }
  return s;
}

// ---------------------------------------------------------------------------------------------

Mounting draw_session_mounting(const Mounting& base, const MountingSpread& spread, std::uint64_t seed) {
  std::mt19937_64 gen(seed ^ 0x6d6f756e74696e67ULL);  // "mounting"
  const auto uniform = [&](double half) {
    return half * (2.0 * (static_cast<double>(gen() >> 11) * 0x1.0p-53) - 1.0);
  };
  const double d2r = M_PI / 180.0;
  Mounting m = base;
  RigidTransform& head = m.T_device_joint[static_cast<size_t>(Role::Head)];
  // The headset turned on the head by `turn` (in its own axes, about the eyes): the joint, seen
  // from the turned device, is turned back.
  const Quat turn = (Quat(Eigen::AngleAxisd(uniform(spread.head_pitch_deg) * d2r, Vec3::UnitX())) *
                     Quat(Eigen::AngleAxisd(uniform(spread.head_roll_deg) * d2r, Vec3::UnitZ())))
                        .normalized();
  head.rotation = (turn.conjugate() * head.rotation).normalized();
  head.position_m = turn.conjugate() * head.position_m;
  const Vec3 eye(uniform(spread.eye_offset_m), uniform(spread.eye_offset_m), uniform(spread.eye_offset_m));
  head.position_m += eye;
  for (Role r : {Role::LeftHand, Role::RightHand}) {
    RigidTransform& T = m.T_device_joint[static_cast<size_t>(r)];
    const Vec3 w(uniform(spread.grip_rotation_deg), uniform(spread.grip_rotation_deg), uniform(spread.grip_rotation_deg));
    const Quat g = quat_from_axis_angle(w * d2r);
    T.rotation = (g.conjugate() * T.rotation).normalized();
    T.position_m = g.conjugate() * T.position_m;
  }
  std::normal_distribution<double> normal(0.0, 1.0);
  for (Role r : kRoles) {
    if (is_xr_role(r)) continue;
    // Any rotation (a normalised 4-D Gaussian is uniform on the sphere of unit quaternions), an
    // offset of a uniform length in a uniform direction, in the joint's frame; T_device_joint is
    // the inverse of the device's pose on the joint.
    const double a = normal(gen), b = normal(gen), c = normal(gen), d = normal(gen);
    const Quat turn = Quat(a, b, c, d).normalized();
    const Vec3 dir = Vec3(normal(gen), normal(gen), normal(gen)).normalized();
    const double length = spread.strap_min_m + (spread.strap_max_m - spread.strap_min_m) * (uniform(0.5) + 0.5);
    const RigidTransform T_joint_device{dir * length, turn};
    m.T_device_joint[static_cast<size_t>(r)] = inverse(T_joint_device);
  }
  return m;
}

std::vector<TrackerSample> with_calibration_pose(const std::vector<TrackerSample>& samples, const BodyReference& reference_in,
                                                 const Mounting& mounting, double rate_hz, double seconds,
                                                 std::optional<std::uint64_t> vary_seed) {
  BodyReference reference = reference_in;
  if (vary_seed) {
    // One person's calibration pose: the reference with normal deviations of its own spreads.
    std::mt19937_64 gen(*vary_seed ^ 0x706f7365ULL);  // "pose"
    std::normal_distribution<double> n(0.0, 1.0);
    const double d2r = M_PI / 180.0;
    reference.head_in_facing = (Quat(Eigen::AngleAxisd(n(gen) * reference.head_pitch_sd_deg * d2r, Vec3::UnitX())) *
                                Quat(Eigen::AngleAxisd(n(gen) * reference.head_roll_sd_deg * d2r, Vec3::UnitZ())) *
                                reference.head_in_facing)
                                   .normalized();
    for (int h = 0; h < 2; ++h) {
      // A rotation whose angle has RMS hand_sd_deg: each axis component sd / sqrt(3).
      const double sd = reference.hand_sd_deg[static_cast<std::size_t>(h)] * d2r / std::sqrt(3.0);
      reference.hand_in_facing[static_cast<std::size_t>(h)] =
          (quat_from_axis_angle(Vec3(n(gen), n(gen), n(gen)) * sd) * reference.hand_in_facing[static_cast<std::size_t>(h)])
              .normalized();
    }
    reference.head_over_wrist_height += n(gen) * reference.head_over_wrist_height_sd;
    reference.head_ahead_of_wrists_m += n(gen) * reference.head_ahead_sd_m;
  }
  const TrackerSample* head0 = nullptr;
  for (const TrackerSample& s : samples)
    if (s.role == Role::Head && s.valid) {
      head0 = &s;
      break;
    }
  if (head0 == nullptr) throw SimError("", "no valid head sample to stand the calibration pose at");
  const TrackerSample joint0 = device_to_joint(*head0, mounting.T_device_joint[0]);
  const double heading = yaw_of((joint0.rotation * reference.head_in_facing.conjugate()).normalized(), Vec3::UnitZ());
  return with_held_pose(samples, calibration_pose_joints(reference, joint0.position_m, heading), mounting, rate_hz, seconds);
}

std::vector<TrackerSample> with_held_pose(const std::vector<TrackerSample>& samples,
                                          const std::array<RigidTransform, kRoleCount>& joints, const Mounting& mounting,
                                          double rate_hz, double seconds, bool body_roles) {
  if (samples.empty()) throw SimError("", "no samples to hold a pose before");
  // The roles held: the body trackers first (as the hands, before the head), then the hands, the head.
  std::array<bool, kRoleCount> carried{}, with_position{};
  for (const TrackerSample& s : samples) {
    carried[static_cast<std::size_t>(s.role)] = true;
    with_position[static_cast<std::size_t>(s.role)] |= s.has_position;
  }
  std::vector<Role> held;
  if (body_roles)
    for (Role r : kRoles)
      if (!is_xr_role(r) && carried[static_cast<std::size_t>(r)]) held.push_back(r);
  held.insert(held.end(), {Role::LeftHand, Role::RightHand, Role::Head});
  const double period_ns = 1e9 / rate_hz;
  const auto n = static_cast<std::int64_t>(seconds * 1e9 / period_ns);
  std::vector<TrackerSample> out;
  out.reserve(samples.size() + static_cast<std::size_t>(n) * kRoleCount);
  // Each instant's hands before its head, so the last head sample (which completes the still
  // second) follows every sample of the pose: nothing of the pose is left after the calibration.
  for (std::int64_t k = n; k >= 1; --k)
    for (Role r : held) {
      const RigidTransform& J = joints[static_cast<std::size_t>(r)];
      const TrackerSample j{samples.front().t_ns - std::llround(static_cast<double>(k) * period_ns), r, true, J.position_m,
                            J.rotation, PoseFrame::Joint};
      TrackerSample d = joint_to_device(j, mounting.T_device_joint[static_cast<std::size_t>(r)]);
      if (!is_xr_role(r) && !with_position[static_cast<std::size_t>(r)]) {
        d.has_position = false;  // an IMU tracker: as its samples in the clip
        d.position_m = Vec3::Zero();
      }
      out.push_back(d);
    }
  out.insert(out.end(), samples.begin(), samples.end());
  return out;
}

std::vector<TrackerSample> simulate_trackers(const Motion& motion, const SimOptions& options) {
  if (std::string err = options.validate(); !err.empty()) throw SimError("", "bad simulator options: " + err);
  return simulate_trackers(TrackerTrajectory(motion), options);
}

std::vector<TrackerSample> simulate_trackers(const TrackerTrajectory& traj, const SimOptions& opt) {
  if (std::string err = opt.validate(); !err.empty()) throw SimError("", "bad simulator options: " + err);
  const double duration_s = static_cast<double>(traj.duration_ns()) * 1e-9;
  const std::int64_t latency_ns = std::llround(opt.latency_ms * 1e6);
  const double pos_sigma_m = opt.position_noise_mm * 1e-3;
  const double rot_sigma_rad = opt.rotation_noise_deg * M_PI / 180.0;
  const double dropout_mean_s = opt.dropout_mean_ms * 1e-3;

  std::vector<TrackerSample> out;
  for (Role role : kRoles) {
    if (std::find(opt.roles.begin(), opt.roles.end(), role) == opt.roles.end()) continue;
    const bool rotation_only = std::find(opt.rotation_only.begin(), opt.rotation_only.end(), role) != opt.rotation_only.end();
    const double rate = opt.rate_of(role);
    const double period_ns = 1e9 / rate;
    // Largest |jitter| that keeps consecutive timestamps of this role increasing.
    const double jitter_bound_ns = std::max(0.0, std::floor(period_ns / 2.0) - 1.0);
    const auto count = static_cast<std::int64_t>(std::floor(duration_s * rate + 1e-9)) + 1;
    Rng pos_rng(opt.seed, role, Effect::PositionNoise);
    Rng rot_rng(opt.seed, role, Effect::RotationNoise);
    Rng jitter_rng(opt.seed, role, Effect::Jitter);
    Rng dropout_rng(opt.seed, role, Effect::Dropout);
    const bool can_drop = role != Role::Head && opt.dropout_rate_hz > 0.0;
    // The current or next tracking-loss episode [lost_from_s, lost_until_s).
    double lost_from_s = std::numeric_limits<double>::infinity(), lost_until_s = 0.0;
    if (can_drop) {
      lost_from_s = dropout_rng.exponential(1.0 / opt.dropout_rate_hz);
      lost_until_s = lost_from_s + dropout_rng.exponential(dropout_mean_s);
    }
    out.reserve(out.size() + static_cast<size_t>(count));
    for (std::int64_t k = 0; k < count; ++k) {
      const std::int64_t t_true_ns = std::llround(static_cast<double>(k) * period_ns);
      const double t_s = static_cast<double>(t_true_ns) * 1e-9;
      TrackerSample s = traj.pose_at(role, std::min(t_true_ns, traj.duration_ns()));
      if (opt.device_mounting) s = joint_to_device(s, opt.device_mounting->T_device_joint[static_cast<size_t>(role)]);
      // Every stream draws for every sample, valid or not, so that one effect's
      // setting does not shift another's random numbers.
      const Vec3 dp(pos_rng.normal(), pos_rng.normal(), pos_rng.normal());
      const Vec3 dr(rot_rng.normal(), rot_rng.normal(), rot_rng.normal());
      const double jitter = jitter_rng.normal();
      if (pos_sigma_m > 0.0) s.position_m += pos_sigma_m * dp;
      if (rot_sigma_rad > 0.0) s.rotation = (quat_from_axis_angle(rot_sigma_rad * dr) * s.rotation).normalized();
      std::int64_t jitter_ns = 0;
      if (opt.jitter_ms > 0.0)
        jitter_ns = std::llround(std::clamp(jitter * opt.jitter_ms * 1e6, -jitter_bound_ns, jitter_bound_ns));
      s.t_ns = t_true_ns + latency_ns + jitter_ns;
      if (can_drop) {
        while (t_s >= lost_until_s) {
          lost_from_s = lost_until_s + dropout_rng.exponential(1.0 / opt.dropout_rate_hz);
          lost_until_s = lost_from_s + dropout_rng.exponential(dropout_mean_s);
        }
        if (t_s >= lost_from_s) {
          s.valid = false;
          s.position_m = Vec3::Zero();
          s.rotation = Quat::Identity();
        }
      }
      if (rotation_only && s.valid) {
        s.has_position = false;
        s.position_m = Vec3::Zero();
      }
      out.push_back(s);
    }
  }
  std::stable_sort(out.begin(), out.end(), [](const TrackerSample& a, const TrackerSample& b) {
    if (a.t_ns != b.t_ns) return a.t_ns < b.t_ns;
    return a.role < b.role;
  });
  return out;
}

}  // namespace bodyd
