#include "bodyd/inference/calibration.h"

#include "bodyd/base/require.h"
#include "bodyd/base/user_error.h"
#include "bodyd/inference/ik.h"

#include "bodyd/motion/limits.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace bodyd {

std::string calibrate_from_head_height(Reconstructor& reconstructor, double head_height_m) {
  if (!(head_height_m >= limits::kMinHeadHeightM && head_height_m <= limits::kMaxHeadHeightM))
    return fmt::format(
        "the head is at y = {:.3f} m, not a plausible standing head height ({} to {} m): stand up straight on "
        "the floor (y = 0) and retry",
        head_height_m, limits::kMinHeadHeightM, limits::kMaxHeadHeightM);
  reconstructor.set_head_height_m(head_height_m);
  return {};
}

double standing_height_from_head(double measured_m, const StandingHeightOptions& options) {
  return measured_m / options.stance_ratio;
}

namespace {
// Head samples closer than this to the previous one kept are not kept (bounds the ring at any
// sample rate; the stillness test does not need more than 250 samples a second).
constexpr std::int64_t kMinSpacingNs = 4'000'000;
constexpr double kBinM = 0.001;  // fallback histogram bin
}  // namespace

std::string validate(const StandingHeightOptions& o) {
  const auto positive = [](double x) { return std::isfinite(x) && x > 0.0; };
  if (!positive(o.still_s) || o.still_s > 10.0) return fmt::format("still_s must be in (0, 10] s, not {}", o.still_s);
  if (!positive(o.max_height_range_m)) return fmt::format("max_height_range_m must be > 0, not {}", o.max_height_range_m);
  if (!positive(o.max_floor_travel_m)) return fmt::format("max_floor_travel_m must be > 0, not {}", o.max_floor_travel_m);
  if (!(o.min_height_m >= 0.0 && o.min_height_m < limits::kMaxHeadHeightM))
    return fmt::format("min_height_m must be in [0, {}) m, not {}", limits::kMaxHeadHeightM, o.min_height_m);
  if (!(o.fallback_after_s >= 0.0 && o.fallback_after_s <= 600.0))
    return fmt::format("fallback_after_s must be in [0, 600] s (0: no fallback), not {}", o.fallback_after_s);
  if (!(o.fallback_percentile >= 0.0 && o.fallback_percentile <= 100.0))
    return fmt::format("fallback_percentile must be in [0, 100], not {}", o.fallback_percentile);
  if (!(o.stance_ratio >= 0.8 && o.stance_ratio <= 1.2))
    return fmt::format("stance_ratio must be in [0.8, 1.2], not {}", o.stance_ratio);
  return {};
}

StandingHeightDetector::StandingHeightDetector(const StandingHeightOptions& options) : options_(options) {
  // The options come from code (the defaults, a test's), never a user: a bad one is a bug.
  BODYD_REQUIRE(validate(options_).empty(), "StandingHeightOptions: " + validate(options_));
  ring_.resize(static_cast<std::size_t>(std::ceil(options_.still_s * 1e9 / kMinSpacingNs)) + 2);
  histogram_.assign(static_cast<std::size_t>(std::ceil(limits::kMaxHeadHeightM / kBinM)) + 1, 0);
}

void StandingHeightDetector::reset() {
  started_ = done_ = false;
  ring_head_ = ring_count_ = 0;
  std::fill(histogram_.begin(), histogram_.end(), 0u);
  histogram_count_ = 0;
  result_.reset();
}

// Whether the ring holds a still stretch of still_s seconds ending at t_ns.
bool StandingHeightDetector::window_still(std::int64_t t_ns) const {
  const auto still_ns = static_cast<std::int64_t>(std::llround(options_.still_s * 1e9));
  const std::size_t n = ring_.size();
  // Oldest entry inside the window [t_ns - still_ns, t_ns]: the stretch must span it all.
  const Entry& oldest = ring_[(ring_head_ + n - ring_count_) % n];
  if (t_ns - oldest.t_ns < still_ns - 1000) return false;
  double lo = oldest.p.y(), hi = lo;
  for (std::size_t i = 0; i < ring_count_; ++i) {
    const Entry& e = ring_[(ring_head_ + n - ring_count_ + i) % n];
    lo = std::min(lo, e.p.y());
    hi = std::max(hi, e.p.y());
    const double dx = e.p.x() - oldest.p.x(), dz = e.p.z() - oldest.p.z();
    if (dx * dx + dz * dz > options_.max_floor_travel_m * options_.max_floor_travel_m) return false;
  }
  return hi - lo <= options_.max_height_range_m && lo >= options_.min_height_m;
}

double StandingHeightDetector::fallback_height() const {
  // Nearest rank over the histogram (1 mm bins): the bin's centre.
  const auto rank = static_cast<std::uint64_t>(
      std::max(1.0, std::ceil(options_.fallback_percentile / 100.0 * static_cast<double>(histogram_count_))));
  std::uint64_t seen = 0;
  for (std::size_t b = 0; b < histogram_.size(); ++b) {
    seen += histogram_[b];
    if (seen >= rank) return (static_cast<double>(b) + 0.5) * kBinM;
  }
  return 0.0;
}

std::optional<StandingHeight> StandingHeightDetector::push(const TrackerSample& sample) {
  if (done_ || sample.role != Role::Head || !sample.valid || !sample.position_m.allFinite()) return std::nullopt;
  const std::size_t n = ring_.size();
  if (!started_) {
    started_ = true;
    first_t_ns_ = sample.t_ns;
  } else {
    const Entry& last = ring_[(ring_head_ + n - 1) % n];
    if (sample.t_ns <= last.t_ns) return std::nullopt;
    if (sample.t_ns - last.t_ns < kMinSpacingNs) return std::nullopt;  // (rates above 250 Hz)
  }
  // Keep only the entries of the last still_s (plus the one just before, which starts it).
  ring_[ring_head_] = Entry{sample.t_ns, sample.position_m};
  ring_head_ = (ring_head_ + 1) % n;
  ring_count_ = std::min(ring_count_ + 1, n);
  const auto still_ns = static_cast<std::int64_t>(std::llround(options_.still_s * 1e9));
  while (ring_count_ > 1 && sample.t_ns - ring_[(ring_head_ + n - ring_count_ + 1) % n].t_ns >= still_ns - 1000)
    --ring_count_;
  const double y = sample.position_m.y();
  if (y >= 0.0 && y < limits::kMaxHeadHeightM) {
    ++histogram_[static_cast<std::size_t>(y / kBinM)];
    ++histogram_count_;
  }

  if (window_still(sample.t_ns)) {
    double sum = 0.0;
    for (std::size_t i = 0; i < ring_count_; ++i) sum += ring_[(ring_head_ + n - ring_count_ + i) % n].p.y();
    const double measured = sum / static_cast<double>(ring_count_);
    done_ = true;
    result_ = StandingHeight{standing_height_from_head(measured, options_), measured, false, sample.t_ns};
    return result_;
  }
  if (options_.fallback_after_s > 0.0 &&
      static_cast<double>(sample.t_ns - first_t_ns_) >= options_.fallback_after_s * 1e9 - 1e3) {
    done_ = true;
    const double measured = fallback_height();
    if (measured < options_.min_height_m) return std::nullopt;  // sitting or crouching: no estimate
    result_ = StandingHeight{standing_height_from_head(measured, options_), measured, true, sample.t_ns};
    return result_;
  }
  return std::nullopt;
}

}  // namespace bodyd

namespace bodyd {

std::string validate(const PoseCalibrationOptions& o) {
  if (!(std::isfinite(o.still_s) && o.still_s >= 0.2 && o.still_s <= 10.0))
    return fmt::format("still_s must be in [0.2, 10] s, not {}", o.still_s);
  if (!(std::isfinite(o.max_position_range_m) && o.max_position_range_m > 0.0 && o.max_position_range_m <= 0.5))
    return fmt::format("max_position_range_m must be in (0, 0.5] m, not {}", o.max_position_range_m);
  if (!(std::isfinite(o.max_rotation_range_deg) && o.max_rotation_range_deg > 0.0 && o.max_rotation_range_deg <= 45.0))
    return fmt::format("max_rotation_range_deg must be in (0, 45] degrees, not {}", o.max_rotation_range_deg);
  if (!(std::isfinite(o.max_head_change_deg) && o.max_head_change_deg > 0.0 && o.max_head_change_deg <= 180.0))
    return fmt::format("max_head_change_deg must be in (0, 180] degrees, not {}", o.max_head_change_deg);
  if (!(std::isfinite(o.max_grip_change_deg) && o.max_grip_change_deg > 0.0 && o.max_grip_change_deg <= 180.0))
    return fmt::format("max_grip_change_deg must be in (0, 180] degrees, not {}", o.max_grip_change_deg);
  return validate(o.height);
}

double max_mounting_change_deg(const PoseCalibrationOptions& options, Role r) {
  return r == Role::Head ? options.max_head_change_deg : options.max_grip_change_deg;
}

BodyJointsInPose body_joints_in_pose(const Skeleton& skeleton) {
  const StandingReference ref = standing_reference(skeleton);
  const int head = skeleton.find("Head");
  if (head < 0 || !(ref.head_height_m > 0.0))
    throw UserError("body trackers' joints in the calibration pose", "the skeleton has no Head joint",
                    "use motion data on the bodyd skeleton (docs/conventions.md)");
  BodyJointsInPose b;
  const Vec3 head_p = ref.global.positions[static_cast<std::size_t>(head)];
  for (Role r : kRoles) {
    if (is_xr_role(r)) continue;
    const int j = skeleton.find(role_joint_name(r));
    if (j < 0) continue;
    const auto i = static_cast<std::size_t>(r);
    b.known[i] = true;
    b.from_head[i] = (ref.global.positions[static_cast<std::size_t>(j)] - head_p) / ref.head_height_m;
    b.in_facing[i] = ref.global.rotations[static_cast<std::size_t>(j)].normalized();
  }
  return b;
}

PoseCalibrator::PoseCalibrator(const BodyReference& reference, const Mounting& defaults,
                               const PoseCalibrationOptions& options, const BodyJointsInPose& body_joints)
    : reference_(reference), defaults_(defaults), options_(options), body_joints_(body_joints) {
  BODYD_REQUIRE(validate(options_).empty(), "PoseCalibrationOptions: " + validate(options_));  // as above
  // Up to 1000 samples a second per role (headsets report 72 to 120 Hz; more are thinned).
  for (auto& w : window_) w.reserve(static_cast<std::size_t>(options_.still_s * 1000.0) + 4);
}

void PoseCalibrator::reset() {
  for (auto& w : window_) w.clear();
  any_invalid_ = {};
  done_ = false;
}

std::optional<PoseCalibration> PoseCalibrator::push(const TrackerSample& s) {
  if (done_) return std::nullopt;
  const int r = static_cast<int>(s.role);
  auto& w = window_[static_cast<std::size_t>(r)];
  if (!s.valid) {
    any_invalid_[static_cast<std::size_t>(r)] = true;
    last_invalid_ns_[static_cast<std::size_t>(r)] = s.t_ns;
    w.clear();  // a hand that was lost is not still
    return std::nullopt;
  }
  if (!s.position_m.allFinite() || !s.rotation.coeffs().allFinite()) return std::nullopt;
  if (!w.empty() && s.t_ns <= w.back().t_ns) return std::nullopt;
  if (!w.empty() && s.t_ns - w.back().t_ns < 1'000'000) return std::nullopt;  // thinned to <= 1 kHz
  if (!w.empty() && w.front().frame != s.frame) w.clear();
  const auto still_ns = static_cast<std::int64_t>(std::llround(options_.still_s * 1e9));
  if (w.size() == w.capacity()) w.erase(w.begin());
  w.push_back(s);
  std::size_t drop = 0;
  while (drop + 1 < w.size() && s.t_ns - w[drop + 1].t_ns >= still_ns) ++drop;
  if (drop > 0) w.erase(w.begin(), w.begin() + static_cast<std::ptrdiff_t>(drop));
  if (s.role != Role::Head) return std::nullopt;
  std::optional<PoseCalibration> c = try_estimate(s.t_ns);
  if (c) done_ = true;
  return c;
}

namespace {

struct WindowStats {
  bool covers = false;   // spans the whole still second
  bool still = false;
  Vec3 mean_p = Vec3::Zero();
  Quat mean_q = Quat::Identity();
  double max_deg = 0.0;
};

WindowStats window_stats(const std::vector<TrackerSample>& w, std::int64_t t_ns, std::int64_t still_ns,
                         const PoseCalibrationOptions& o) {
  WindowStats st;
  if (w.size() < 3 || t_ns - w.front().t_ns < still_ns - 2'000'000 || t_ns - w.back().t_ns > 100'000'000) return st;
  st.covers = true;
  // Sign-aligned mean of the rotations (mean_rotation's rule), without a copy: this runs at every
  // head sample while a calibration waits.
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  const Eigen::Vector4d first = w.front().rotation.coeffs();
  for (const TrackerSample& s : w) {
    st.mean_p += s.position_m;
    const Eigen::Vector4d v = s.rotation.coeffs();
    sum += v.dot(first) < 0.0 ? Eigen::Vector4d(-v) : v;
  }
  st.mean_p /= static_cast<double>(w.size());
  st.mean_q.coeffs() = sum.normalized();
  double max_d = 0.0;
  for (const TrackerSample& s : w) {
    max_d = std::max(max_d, (s.position_m - st.mean_p).norm());
    st.max_deg = std::max(st.max_deg, geodesic_angle(s.rotation, st.mean_q) * 180.0 / M_PI);
  }
  st.still = max_d <= o.max_position_range_m && st.max_deg <= o.max_rotation_range_deg;
  return st;
}

}  // namespace

std::optional<PoseCalibration> PoseCalibrator::try_estimate(std::int64_t t_ns) const {
  const auto still_ns = static_cast<std::int64_t>(std::llround(options_.still_s * 1e9));
  std::array<WindowStats, kRoleCount> st;
  st[0] = window_stats(window_[0], t_ns, still_ns, options_);
  const WindowStats& head = st[0];
  if (!head.covers || !head.still) return std::nullopt;  // the hands are not looked at before
  for (int h = 1; h <= 2; ++h) st[static_cast<size_t>(h)] = window_stats(window_[static_cast<size_t>(h)], t_ns, still_ns, options_);
  std::array<bool, 2> hand_used{};
  for (int h = 0; h < 2; ++h) {
    const WindowStats& hs = st[static_cast<size_t>(h + 1)];
    const bool lost_recently =
        any_invalid_[static_cast<size_t>(h + 1)] && t_ns - last_invalid_ns_[static_cast<size_t>(h + 1)] < still_ns;
    const bool tracked = !window_[static_cast<size_t>(h + 1)].empty() && !lost_recently;
    if (tracked && !hs.covers) return std::nullopt;  // wait until the hand's second is complete
    if (tracked && !hs.still) return std::nullopt;   // a moving hand: not the calibration pose
    hand_used[static_cast<size_t>(h)] = tracked;
  }
  // Body trackers with device poses: each that is tracked must complete a still second too.
  std::array<bool, kRoleCount> body_used{};
  for (Role r : kRoles) {
    const auto i = static_cast<std::size_t>(r);
    if (is_xr_role(r) || !body_joints_.known[i] || window_[i].empty() || window_[i].front().frame != PoseFrame::Device)
      continue;
    if (any_invalid_[i] && t_ns - last_invalid_ns_[i] < still_ns) continue;  // lost in the second: left out
    st[i] = window_stats(window_[i], t_ns, still_ns, options_);
    if (!st[i].covers || !st[i].still) return std::nullopt;
    body_used[i] = true;
  }
  PoseCalibration c;
  c.t_ns = t_ns;
  c.mounting = defaults_;
  c.device_frames = window_[0].front().frame == PoseFrame::Device;
  for (Role r : kRoles) c.motion_deg[static_cast<size_t>(r)] = st[static_cast<size_t>(r)].max_deg;
  if (c.device_frames) {
    const Quat F = facing_from_device(head.mean_q);
    RigidTransform& Th = c.mounting.T_device_joint[0];
    const RigidTransform& Dh = defaults_.T_device_joint[0];
    Th.rotation = (head.mean_q.conjugate() * F * reference_.head_in_facing).normalized();
    if (!options_.estimate_head_roll) {
      // Keep only the pitch of the headset's turn on the head (its twist about the device's +X):
      // T = turn^-1 * default, so turn = default * T^-1.
      const Quat turn = (Dh.rotation * Th.rotation.conjugate()).normalized();
      Quat pitch(turn.w(), turn.x(), 0.0, 0.0);
      pitch = pitch.norm() > 1e-12 ? pitch.normalized() : Quat::Identity();
      Th.rotation = (pitch.conjugate() * Dh.rotation).normalized();
    }
    // The eye offset is the head's: it turns with the headset's turn on the head.
    Th.position_m = (Th.rotation * Dh.rotation.conjugate()) * Dh.position_m;
    c.measured[0] = true;
    c.rotation_sd_deg[0] = std::hypot(reference_.head_pitch_sd_deg, reference_.head_roll_sd_deg);
    c.eye_offset_sd_cm = 100.0 * std::hypot(kEyeAboveHeadJointM, kEyeAheadOfHeadJointM) * 0.2;  // the prior's spread
    std::array<Vec3, 2> wrist{};
    for (int h = 0; h < 2; ++h) {
      if (!hand_used[static_cast<size_t>(h)]) continue;
      const WindowStats& hs = st[static_cast<size_t>(h + 1)];
      if (window_[static_cast<size_t>(h + 1)].front().frame != PoseFrame::Device) continue;
      RigidTransform& T = c.mounting.T_device_joint[static_cast<size_t>(h + 1)];
      const RigidTransform& D = defaults_.T_device_joint[static_cast<size_t>(h + 1)];
      T.rotation = (hs.mean_q.conjugate() * F * reference_.hand_in_facing[static_cast<size_t>(h)]).normalized();
      // The controller turned in the hand about its grip point: the wrist offset turns with it.
      T.position_m = (T.rotation * D.rotation.conjugate()) * D.position_m;
      wrist[static_cast<size_t>(h)] = hs.mean_p + hs.mean_q * T.position_m;
      c.measured[static_cast<size_t>(h + 1)] = true;
      c.rotation_sd_deg[static_cast<size_t>(h + 1)] = reference_.hand_sd_deg[static_cast<size_t>(h)];
    }
    if (options_.estimate_eye_offset && c.measured[1] && c.measured[2]) {
      // The Head joint above the wrists' midpoint at the reference's height and depth.
      const Vec3 mid = 0.5 * (wrist[0] + wrist[1]);
      const Quat Fi = F.conjugate();
      Vec3 h = Fi * head.mean_p;  // in facing axes (a turn about +Y keeps heights)
      h.x() = (Fi * mid).x();  // centred between the wrists of a symmetric stance
      h.y() = reference_.head_over_wrist_height * mid.y();
      h.z() = (Fi * mid).z() + reference_.head_ahead_of_wrists_m;
      Th.position_m = head.mean_q.conjugate() * (F * h - head.mean_p);
      c.eye_offset_sd_cm = 100.0 * std::hypot(reference_.head_over_wrist_height_sd * mid.y(), reference_.head_ahead_sd_m);
    }
    const Vec3 head_joint = head.mean_p + head.mean_q * Th.position_m;
    c.measured_head_y_m = head_joint.y();
    // Body trackers: the joint as in the reference standing pose under the Head joint, at the
    // user's standing height, turned to the headset's heading.
    const double standing_m = standing_height_from_head(c.measured_head_y_m, options_.height);
    for (Role r : kRoles) {
      const auto i = static_cast<std::size_t>(r);
      if (!body_used[i]) continue;
      const Vec3 joint_p = head_joint + F * (body_joints_.from_head[i] * standing_m);
      RigidTransform& T = c.mounting.T_device_joint[i];
      T.rotation = (st[i].mean_q.conjugate() * F * body_joints_.in_facing[i]).normalized();
      const bool has_position = window_[i].back().has_position;
      // Only the height difference is kept: a person's stance moves the hips and feet sideways and
      // ahead of the reference's by more than a strap's offset, while the joints' heights under
      // the head hold (docs/evaluation.md, "Body trackers' mountings": offset error 4.6 cm this
      // way against 8.8 cm with the reference's whole offset). The whole offset still says
      // whether the tracker is near its joint at all (pose_problem).
      const Vec3 off = joint_p - st[i].mean_p;
      T.position_m = has_position ? Vec3(st[i].mean_q.conjugate() * Vec3(0.0, off.y(), 0.0)) : Vec3::Zero();
      c.measured[i] = true;
      c.rotation_sd_deg[i] = kBodyTrackerPoseSdDeg;
      c.offset_cm[i] = has_position ? 100.0 * off.norm() : 0.0;
    }
    std::array<Vec3, kRoleCount> device_p{};
    for (std::size_t i = 0; i < kRoleCount; ++i) device_p[i] = st[i].mean_p;
    if (std::string why = pose_problem(c, device_p); !why.empty()) {
      refusal_ = std::move(why);
      return std::nullopt;
    }
  } else {
    c.measured_head_y_m = head.mean_p.y();
  }
  c.head_height_m = standing_height_from_head(c.measured_head_y_m, options_.height);
  refusal_.clear();
  return c;
}

std::string PoseCalibrator::pose_problem(const PoseCalibration& c, const std::array<Vec3, kRoleCount>& device_p) const {
  const double head_y = device_p[0].y();
  for (int h = 1; h <= 2; ++h) {
    if (!c.measured[static_cast<size_t>(h)]) continue;
    const Vec3& p = device_p[static_cast<size_t>(h)];
    const double horizontal = std::hypot(p.x() - device_p[0].x(), p.z() - device_p[0].z());
    if (p.y() < 0.35 * head_y || p.y() > 0.8 * head_y || horizontal > 0.45) {
      refusal_clear_ = p.y() < (0.35 - kClearHandHeightRatio) * head_y ||
                       p.y() > (0.8 + kClearHandHeightRatio) * head_y || horizontal > 0.45 + kClearHandDistanceM;
      return fmt::format("the {} is not hanging at your side ({:.2f} m high with the headset at {:.2f} m, {:.2f} m "
                         "from it horizontally): let both arms hang relaxed",
                         role_name(kRoles[static_cast<size_t>(h)]), p.y(), head_y, horizontal);
    }
    const double change = mounting_difference(c.mounting.T_device_joint[static_cast<size_t>(h)],
                                              defaults_.T_device_joint[static_cast<size_t>(h)])
                              .angle_deg;
    const double limit = max_mounting_change_deg(options_, kRoles[static_cast<size_t>(h)]);
    if (change > limit) {
      refusal_clear_ = change > limit + kClearTurnDeg;
      return fmt::format("the {} controller is turned {:.0f} degrees from pointing ahead: hold each controller "
                         "naturally, pointing forward",
                         role_name(kRoles[static_cast<size_t>(h)]), change);
    }
  }
  for (Role r : kRoles) {
    const auto i = static_cast<std::size_t>(r);
    if (is_xr_role(r) || !c.measured[i]) continue;
    if (c.offset_cm[i] > 100.0 * kMaxBodyTrackerOffsetM) {
      refusal_clear_ = true;  // the next still second finds the tracker where it is
      return fmt::format("the {} tracker is {:.0f} cm from your {} in the calibration pose (at most {:.0f}): is it "
                         "strapped there, and is its role in SteamVR or the sender the right one?",
                         role_name(r), c.offset_cm[i], role_joint_name(r), 100.0 * kMaxBodyTrackerOffsetM);
    }
    const std::string_view name = role_name(r);
    const bool left = name.rfind("left_", 0) == 0, right = name.rfind("right_", 0) == 0;
    if ((left || right) && window_[i].back().has_position) {
      // Its side of the headset in the facing frame (+X is the body's left).
      const Quat F = facing_from_device(window_[0].back().rotation);
      const double lateral = (F.conjugate() * (device_p[i] - device_p[0])).x();
      if ((left && lateral < -kMaxBodyTrackerWrongSideM) || (right && lateral > kMaxBodyTrackerWrongSideM)) {
        refusal_clear_ = true;
        return fmt::format("the {} tracker is on your {} side ({:.0f} cm from the headset's centre line): are the left "
                           "and right trackers' roles swapped?",
                           name, left ? "right" : "left", 100.0 * std::abs(lateral));
      }
    }
  }
  const double head_change = mounting_difference(c.mounting.T_device_joint[0], defaults_.T_device_joint[0]).angle_deg;
  const double head_limit = max_mounting_change_deg(options_, Role::Head);
  if (head_change > head_limit) {
    refusal_clear_ = head_change > head_limit + kClearTurnDeg;
    return fmt::format("the headset is tilted {:.0f} degrees from level: look straight ahead", head_change);
  }
  return {};
}

}  // namespace bodyd
