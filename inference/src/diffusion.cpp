#include "bodyd/inference/diffusion.h"

#include "bodyd/inference/features.h"
#include "bodyd/inference/ik.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

namespace bodyd {

namespace {
// The low-pass of the head correction (OneEuroOptions::head_correction_cutoff_hz, position only)
// and of the smoothed anchor (anchor_cutoff_hz): a One Euro filter with position and rotation at
// `cutoff_hz`, a little speed adaptation and no noise gate of its own (the tracker filter's gain
// decides how much of it applies). An unused one (cutoff 0) gets 1 Hz.
OneEuroOptions smoothing_options(double cutoff_hz) {
  OneEuroOptions o;
  o.min_cutoff_hz = o.rot_min_cutoff_hz = cutoff_hz > 0.0 ? cutoff_hz : 1.0;
  o.beta_per_m_s = 1.0;
  o.noise_gate = false;
  return o;
}

constexpr double kNsPerS = 1e9;

// push() checks positions against the user's bound before scaling them into the model's
// size; the history, holding scaled positions, only needs them finite.
TrackerHistoryOptions model_scale_history(TrackerHistoryOptions options) {
  options.max_abs_position_m = std::numeric_limits<double>::max();
  return options;
}

bool finite(const GlobalPose& g) {
  for (size_t j = 0; j < g.positions.size(); ++j)
    if (!g.positions[j].allFinite() || !g.rotations[j].coeffs().allFinite()) return false;
  return true;
}
}  // namespace

std::string validate_foot_lock(const DiffusionOptions& o) {
  const auto in = [](double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; };
  if (!in(o.contact_on, 0.0, 1.0) || !in(o.contact_off, 0.0, 1.0))
    return fmt::format("foot lock contact_on and contact_off must be in [0, 1], not {} and {}", o.contact_on,
                       o.contact_off);
  if (!in(o.foot_unlock_distance_m, 0.0, 100.0))
    return fmt::format("foot lock foot_unlock_distance_m must be in [0, 100] m, not {}", o.foot_unlock_distance_m);
  if (!in(o.foot_contact_speed_m_s, 0.0, 100.0))
    return fmt::format("foot lock foot_contact_speed_m_s must be in [0, 100] m/s, not {}", o.foot_contact_speed_m_s);
  if (!(std::isfinite(o.foot_release_half_life_s) && o.foot_release_half_life_s > 0.0 &&
        o.foot_release_half_life_s <= 100.0))
    return fmt::format("foot lock foot_release_half_life_s must be in (0, 100] s, not {}", o.foot_release_half_life_s);
  if (!in(o.leg_position_blend, 0.0, 1.0))
    return fmt::format("leg_position_blend must be in [0, 1], not {}", o.leg_position_blend);
  if (!in(o.elbow_pole_bias_m, 0.0, 10.0))
    return fmt::format("elbow_pole_bias_m must be in [0, 10] m, not {}", o.elbow_pole_bias_m);
  return {};
}

void bend_legs_toward_predicted_ankles(const Skeleton& skeleton, const std::array<std::optional<TwoBoneChain>, 2>& legs,
                                       features::ConstFrame frame, const features::Canonical& canon, double blend,
                                       Pose& pose, GlobalPose& global) {
  // The network predicts every joint's position beside its rotation; decoding uses the rotations
  // (and the Hips position), so an ankle sits where three rotations about the hip, knee and ankle
  // put it. Its predicted position is a second estimate (docs/models.md, "The legs toward the
  // predicted ankles").
  if (!(blend > 0.0)) return;
  for (const auto& leg : legs) {
    if (!leg) continue;
    Vec3 ankle;
    Quat unused;
    features::decode_joint(leg->end, frame, canon, ankle, unused);
    const auto end = static_cast<size_t>(leg->end);
    TwoBoneTarget target;
    target.position_m = global.positions[end] + blend * (ankle - global.positions[end]);
    target.rotation = global.rotations[end];
    (void)solve_two_bone_ik(skeleton, *leg, target, pose, global);
  }
}

DiffusionReconstructor::DiffusionReconstructor(std::shared_ptr<const inference::Model> model,
                                               const DiffusionOptions& options)
    : model_(std::move(model)),
      network_(inference::make_denoiser(*model_, options.weights)),
      options_(options),
      sampler_(network_, inference::SamplerOptions{options.steps, options.guidance, 0.0f}, options.seed),
      skeleton_(model_->skeleton),
      user_skeleton_(model_->skeleton),
      history_(model_scale_history(options.history)),
      filter_(options.filter),
      head_correction_(smoothing_options(options.filter.head_correction_cutoff_hz)),
      anchor_filter_(smoothing_options(options.filter.anchor_cutoff_hz)) {
  // The options come from the user's flags and config keys; the model from the user's file.
  if (std::string err = validate(options.filter); !err.empty()) throw UserError("", err);
  if (std::string err = validate(options.body_filter); !err.empty()) throw UserError("", err);
  if (std::string err = validate_foot_lock(options); !err.empty()) throw UserError("", err);
  if (std::string err = features::check_skeleton(skeleton_); !err.empty())
    throw UserError(model_->source, "model skeleton: " + err, "use a model trained on the bodyd skeleton");
  if (network_->dim() != features::kDim)
    throw UserError(model_->source,
                    fmt::format("model has D = {}, the features have {}", network_->dim(), features::kDim),
                    "use a model trained for this version");
  if (!(model_->fps > 0)) throw UserError(model_->source, "model fps must be > 0");
  W_ = network_->frames();
  frame_dt_ns_ = static_cast<std::int64_t>(std::llround(kNsPerS / model_->fps));
  // Reference height: the skeleton's standing head height (the same definition as the IK baseline's).
  model_height_m_ = standing_head_height_m(skeleton_);
  arms_[0] = find_two_bone_chain(skeleton_, "UpperArm_L", "LowerArm_L", "Hand_L");
  arms_[1] = find_two_bone_chain(skeleton_, "UpperArm_R", "LowerArm_R", "Hand_R");
  legs_[0] = find_two_bone_chain(skeleton_, "UpperLeg_L", "LowerLeg_L", "Foot_L");
  legs_[1] = find_two_bone_chain(skeleton_, "UpperLeg_R", "LowerLeg_R", "Foot_R");
  upper_body_ = find_upper_body(skeleton_);

  const size_t n = static_cast<size_t>(W_) * features::kDim;
  obs_.assign(n, 0.0f);
  mask_.assign(n, 0.0f);
  out_.assign(n, 0.0f);
  noise_.assign(n, 0.0f);
  inference::Rng rng(options_.seed);
  for (float& v : noise_) v = rng.normal();
  const int capacity = std::max(options_.emitted_capacity, W_ + 2);
  emitted_.resize(static_cast<size_t>(capacity));
  for (Emitted& e : emitted_) {
    e.global.positions.resize(static_cast<size_t>(skeleton_.size()));
    e.global.rotations.resize(static_cast<size_t>(skeleton_.size()));
  }
  scratch_global_ = emitted_[0].global;
  out_global_ = emitted_[0].global;
  scratch_pose_ = rest_pose(skeleton_);
  body_filter_ = PoseFilter(options_.body_filter, skeleton_.size(), features::kHips);
}

void DiffusionReconstructor::push(const TrackerSample& sample) {
  // The second wall (issue 11): check the values as the user gave them; once scaled into the
  // model's size they are bounded, so the history only re-checks finiteness.
  if (!tracker_sample_plausible(sample, options_.history.max_abs_position_m)) {
    history_.note_refused();
    return;
  }
  TrackerSample s = sample;
  s.position_m *= scale_;  // into the model's body size
  (void)history_.push(filter_.filter(s));
}

void DiffusionReconstructor::reset() {
  history_.clear();
  filter_.reset();
  body_filter_.reset();
  head_correction_.reset();
  anchor_filter_.reset();
  emitted_head_ = emitted_count_ = 0;
  emitted_dropped_ = false;
  have_last_ = false;
  hand_ease_ = {};
  foot_ease_ = {};
  hips_ease_ = {};
  elbow_ease_ = {};
  knee_ease_ = {};
  foot_locked_ = {};
  foot_release_offset_ = {Vec3::Zero(), Vec3::Zero()};
  lost_head_ = {};
  sampler_.reseed(options_.seed);
}

void DiffusionReconstructor::set_head_height_m(double height_m) {
  // Each role's newest sample, back in the user's units: kept across the reset below, so a
  // tracker that was reporting still counts as tracked in the next pose (issue 20 item 9: the
  // pose after the auto calibration said neither hand was tracking, because the hands' samples
  // had been dropped and their next ones had not arrived yet).
  std::array<std::optional<TrackerSample>, kRoleCount> newest{};
  for (Role role : kRoles)
    if (const TrackerSample* s = history_.newest(role)) {
      newest[static_cast<size_t>(role)] = *s;
      newest[static_cast<size_t>(role)]->position_m /= scale_;
    }
  scale_ = height_m > 0 ? model_height_m_ / height_m : 1.0;
  for (size_t j = 0; j < user_skeleton_.offsets.size(); ++j) {
    user_skeleton_.offsets[j] = skeleton_.offsets[j] / scale_;
    if (skeleton_.end_sites[j]) user_skeleton_.end_sites[j] = *skeleton_.end_sites[j] / scale_;
  }
  // The window's samples and emitted frames are in the old scale: start over (calibration
  // happens while standing), from the newest sample of each role in the new scale.
  reset();
  for (const std::optional<TrackerSample>& s : newest)
    if (s) {
      TrackerSample scaled = *s;
      scaled.position_m *= scale_;
      (void)history_.push(filter_.filter(scaled));
    }
}

bool DiffusionReconstructor::emitted_at(std::int64_t t_ns, GlobalPose& out, std::array<bool, 2>& contact,
                                        const Emitted** exact) const {
  if (exact != nullptr) *exact = nullptr;
  if (emitted_count_ == 0) return false;
  constexpr std::int64_t kTolNs = 1'000'000;  // 1 ms: treat as the same frame
  const Emitted& oldest = emitted(0);
  const Emitted& newest = emitted(emitted_count_ - 1);
  // The frame `e` as the answer: its address in *exact, or its pose copied into `out`.
  auto copy = [&](const Emitted& e) {
    contact = e.contact;
    if (exact != nullptr) {
      *exact = &e;
      return true;
    }
    for (size_t j = 0; j < out.positions.size(); ++j) {
      out.positions[j] = e.global.positions[j];
      out.rotations[j] = e.global.rotations[j];
    }
    return true;
  };
  if (t_ns > newest.t_ns + kTolNs) return false;
  if (t_ns < oldest.t_ns - kTolNs) {
    // Before the first emitted frame: pad with it, as the training windows pad a clip's start with
    // its first frame. Once older frames have been dropped from the ring, there is no padding.
    if (emitted_dropped_) return false;
    return copy(oldest);
  }
  // Last emitted frame at or before t_ns (binary search over the ring, times increase).
  int lo = 0, hi = emitted_count_ - 1;
  while (lo < hi) {
    const int mid = (lo + hi + 1) / 2;
    if (emitted(mid).t_ns <= t_ns) lo = mid; else hi = mid - 1;
  }
  const Emitted& a = emitted(lo);
  if (std::llabs(a.t_ns - t_ns) <= kTolNs || lo + 1 >= emitted_count_) return copy(a);
  const Emitted& b = emitted(lo + 1);
  if (std::llabs(b.t_ns - t_ns) <= kTolNs) return copy(b);
  // Emitted frames further apart than two model frames leave a gap: not a usable observation.
  if (b.t_ns - a.t_ns > 2 * frame_dt_ns_) return false;
  const double u = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  for (size_t j = 0; j < out.positions.size(); ++j) {
    out.positions[j] = (1 - u) * a.global.positions[j] + u * b.global.positions[j];
    out.rotations[j] = slerp(a.global.rotations[j], b.global.rotations[j], u);
  }
  contact = u < 0.5 ? a.contact : b.contact;
  return true;
}

bool DiffusionReconstructor::tracker_at(Role role, std::int64_t t_ns, std::int64_t now_ns, Vec3& p, Quat& q) const {
  bool has_position = false;
  return observed_at(role, t_ns, now_ns, p, q, has_position) && has_position;
}

bool DiffusionReconstructor::observed_at(Role role, std::int64_t t_ns, std::int64_t now_ns, Vec3& p, Quat& q,
                                         bool& has_position) const {
  TrackerSample s;
  const TrackerSample* first = history_.first_valid(role);
  if (first != nullptr && t_ns < first->t_ns) {
    // Before the first observation: the window is padded with it (docs/conventions.md, online protocol).
    p = first->position_m;
    q = first->rotation;
    has_position = first->has_position;
    return true;
  }
  if (!history_.query(role, t_ns, now_ns, s)) return false;
  p = s.position_m;
  q = s.rotation;
  has_position = s.has_position;
  return true;
}

void DiffusionReconstructor::lock_feet(const std::array<bool, 2>& contact, const std::array<bool, 2>& placed,
                                       double dt_s) {
  // A foot the model says is planted may not slide: its toe follows the prediction horizontally
  // at most at foot_contact_speed_m_s (below what reads as skating), starting from where it was
  // emitted last; the leg swings about the hip to put it there. When the foot
  // lifts, the remaining correction decays so the foot eases back to the prediction.
  const double release = std::exp2(-dt_s / std::max(1e-6, options_.foot_release_half_life_s));
  const double max_step = options_.foot_contact_speed_m_s * dt_s;
  const int toes[2] = {features::kToesL, features::kToesR};
  for (size_t s = 0; s < 2; ++s) {
    if (!legs_[s]) continue;
    const Vec3 toe = out_global_.positions[static_cast<size_t>(toes[s])];
    if (placed[s]) {
      // On its tracker (fit_tracked_legs): not moved; the lock starts from here when the tracker goes.
      foot_locked_[s] = contact[s];
      foot_lock_toe_[s] = toe;
      foot_release_offset_[s] = Vec3::Zero();
      continue;
    }
    Vec3 correction = Vec3::Zero();
    if (contact[s] && foot_locked_[s] && dt_s > 0) {
      // Horizontal move from the last emitted toe toward the prediction, speed-limited.
      Vec3 step = toe - foot_lock_toe_[s];
      step.y() = 0;
      const double n = step.norm();
      if (n > options_.foot_unlock_distance_m) {
        correction = Vec3::Zero();  // the prediction moved far away: re-plant where it is
      } else {
        if (n > max_step) step *= max_step / n;
        Vec3 target = foot_lock_toe_[s] + step;
        target.y() = toe.y();
        correction = target - toe;
      }
      foot_release_offset_[s] = correction;
    } else {
      foot_release_offset_[s] *= release;
      correction = foot_release_offset_[s];
    }
    foot_locked_[s] = contact[s];
    if (correction.squaredNorm() > 1e-12) {
      // Swing the whole leg about the hip so the toe moves by `correction` (to first order; the
      // corrections are centimetres on a ~90 cm leg). Unlike two-bone IK this never flips a
      // nearly straight knee, which would show as jitter.
      const auto upper = static_cast<size_t>(legs_[s]->upper);
      const auto parent = static_cast<size_t>(skeleton_.parents[upper]);
      const Vec3 hip = out_global_.positions[upper];
      const Quat swing = Quat::FromTwoVectors(toe - hip, toe + correction - hip);
      const Quat global_upper = (swing * out_global_.rotations[upper]).normalized();
      scratch_pose_.local_rotations[upper] = (out_global_.rotations[parent].conjugate() * global_upper).normalized();
      forward_kinematics(skeleton_, scratch_pose_, out_global_);
    }
    foot_lock_toe_[s] = out_global_.positions[static_cast<size_t>(toes[s])];
  }
}

features::Canonical DiffusionReconstructor::anchor(std::int64_t t_ns, const HeadNow& head) {
  if (!(options_.filter.anchor_cutoff_hz > 0.0)) return features::canonical_from_head(head.p, head.q);
  if (!head.valid) {
    anchor_filter_.reset();  // starts over with the head's next sample
    return features::canonical_from_head(head.p, head.q);
  }
  TrackerSample sample;
  sample.t_ns = t_ns;
  sample.valid = true;
  sample.position_m = head.p;
  sample.rotation = head.q;
  const TrackerSample smooth = anchor_filter_.filter(sample);  // kept up to date on clean heads too
  const OneEuroFilter& head_filter = filter_.of(Role::Head);
  const double position_gain = head_filter.position_gain(), rotation_gain = head_filter.rotation_gain();
  if (position_gain <= 0.0 && rotation_gain <= 0.0) return features::canonical_from_head(head.p, head.q);
  const Vec3 p = head.p + position_gain * (smooth.position_m - head.p);
  const Quat q = head.q.slerp(rotation_gain, smooth.rotation).normalized();
  return features::canonical_from_head(p, q);
}

// reconstruct() in its stages: the head (the window's anchor), the window of observations, the
// network's newest frame, the tracked joints (head and hands), the feet, the arms, then what is
// kept for the next windows and what goes out at the user's size.
bool DiffusionReconstructor::reconstruct(std::int64_t t_ns, BodyPose& out) {
  if (have_last_ && t_ns <= last_t_ns_) return false;  // times must increase
  HeadNow head;
  if (!head_now(t_ns, head)) return false;
  const features::Canonical canon = anchor(t_ns, head);
  TrackersNow trackers;
  build_window(t_ns, head, canon, trackers);
  std::array<bool, 2> contact{};
  sample_newest_frame(canon, contact);
  filter_body(t_ns);

  const double frame_dt_s = have_last_ ? static_cast<double>(t_ns - last_t_ns_) / kNsPerS : 0.0;
  TrackedTargets targets;
  const HandGoals hands = hand_goals(t_ns, frame_dt_s, trackers, targets);
  fit_tracked_joints(t_ns, frame_dt_s, head, trackers, targets);
  const std::array<bool, 2> feet_placed = fit_tracked_legs(t_ns, frame_dt_s, trackers);
  if (options_.foot_lock) lock_feet(contact, feet_placed, frame_dt_s);
  fit_arms(t_ns, frame_dt_s, canon, hands, trackers);

  // A non-finite pose (from inputs within limits this would be a network bug) is dropped, never
  // remembered: fed back as an observation it would poison every later window. The per-frame
  // state it may have touched starts over.
  if (!finite(out_global_)) {
    ++refused_outputs_;
    for (JointEase& e : hand_ease_) e.source = JointSource::model;
    for (JointEase& e : foot_ease_) e.source = JointSource::model;
    hips_ease_.source = JointSource::model;
    for (JointEase& e : elbow_ease_) e.source = JointSource::model;
    for (JointEase& e : knee_ease_) e.source = JointSource::model;
    foot_locked_ = {};
    foot_release_offset_ = {Vec3::Zero(), Vec3::Zero()};
    body_filter_.reset();
    return false;
  }
  remember_emitted(t_ns, contact);
  last_t_ns_ = t_ns;
  have_last_ = true;
  write_user_pose(t_ns, contact, trackers.valid, out);
  return true;
}

bool DiffusionReconstructor::head_now(std::int64_t t_ns, HeadNow& head) {
  head.valid = tracker_at(Role::Head, t_ns, t_ns, head.p, head.q);
  if (head.valid) return true;
  // Head lost: the body stays where the last valid head sample put it, unless both hands are
  // tracked now and were then: the body then goes where the hands went (their midpoint's
  // horizontal displacement since the head's last sample; a walking user's hands move with the
  // body, their swing cancels between the two), for at most kHeadDeadReckoningNs. So a headset
  // tracked by rotation only for a moment does not leave the body standing while the user walks.
  const TrackerSample* last = history_.newest_valid_at_or_before(Role::Head, t_ns);
  if (last == nullptr) return false;
  head.p = last->position_m;
  head.q = last->rotation;
  if (t_ns - last->t_ns > kHeadDeadReckoningNs) return true;
  // The hands' midpoint when the head was last seen, taken once per loss (the history may not
  // keep that far back for the whole loss).
  if (lost_head_.t_ns != last->t_ns) {
    lost_head_.t_ns = last->t_ns;
    lost_head_.hands_ok = true;
    lost_head_.hands_mid = Vec3::Zero();
    for (Role hand : {Role::LeftHand, Role::RightHand}) {
      Vec3 p;
      Quat q;
      lost_head_.hands_ok = lost_head_.hands_ok && tracker_at(hand, last->t_ns, last->t_ns, p, q);
      lost_head_.hands_mid += 0.5 * p;
    }
  }
  if (!lost_head_.hands_ok) return true;
  Vec3 now_mid = Vec3::Zero();
  for (Role hand : {Role::LeftHand, Role::RightHand}) {
    Vec3 p;
    Quat q;
    if (!tracker_at(hand, t_ns, t_ns, p, q)) return true;
    now_mid += 0.5 * p;
  }
  head.p.x() += now_mid.x() - lost_head_.hands_mid.x();
  head.p.z() += now_mid.z() - lost_head_.hands_mid.z();
  return true;
}

void DiffusionReconstructor::build_window(std::int64_t t_ns, const HeadNow& head, const features::Canonical& canon,
                                          TrackersNow& trackers) {
  // Observations and mask, in feature units, then normalised: the emitted frames (all but the
  // newest) and the trackers.
  std::fill(obs_.begin(), obs_.end(), 0.0f);
  std::fill(mask_.begin(), mask_.end(), 0.0f);
  for (int w = 0; w < W_; ++w) {
    const std::int64_t tw = t_ns - static_cast<std::int64_t>(W_ - 1 - w) * frame_dt_ns_;
    features::Frame frame(obs_.data() + static_cast<size_t>(w) * features::kDim, features::kDim);
    float* m = mask_.data() + static_cast<size_t>(w) * features::kDim;
    std::array<bool, 2> contact{};
    const Emitted* exact = nullptr;
    if (w < W_ - 1 && emitted_at(tw, scratch_global_, contact, &exact)) {
      // An emitted frame's world entries were kept when it was emitted: only this window's
      // rotation is applied (a 64-frame window spent a third of its frame encoding poses).
      if (exact != nullptr)
        features::encode_world_entries(exact->world, contact, canon, frame);
      else
        features::encode_pose(scratch_global_, contact, canon, frame);
      std::fill(m, m + features::kDim, 1.0f);
    }
    for (Role role : kRoles) {
      Vec3 p = Vec3::Zero();
      Quat q;
      // A body tracker may have a rotation only (an IMU tracker): then only its joint's rotation
      // entries are observed. The headset and controllers need their positions.
      bool has_position = true;
      const bool ok = (w == W_ - 1 && role == Role::Head) ? (p = head.p, q = head.q, head.valid)
                      : is_xr_role(role)                  ? tracker_at(role, tw, t_ns, p, q)
                                                          : observed_at(role, tw, t_ns, p, q, has_position);
      if (w == W_ - 1) {
        trackers.valid[static_cast<size_t>(role)] = ok;
        trackers.has_position[static_cast<size_t>(role)] = ok && has_position;
        trackers.p[static_cast<size_t>(role)] = p;
        trackers.q[static_cast<size_t>(role)] = q;
      }
      if (!ok) continue;
      const auto entries = features::tracker_entries(role);
      // Without a position only the rotation entries are the tracker's: the position entries keep
      // what they hold (an emitted frame's, observed as such; else nothing observed).
      std::array<float, 3> kept{};
      for (std::size_t k = 0; k < 3; ++k) kept[k] = frame[static_cast<std::size_t>(entries[k])];
      features::encode_joint(features::tracker_joint(role), p, q, canon, frame);
      if (!has_position)
        for (std::size_t k = 0; k < 3; ++k) frame[static_cast<std::size_t>(entries[k])] = kept[k];
      for (std::size_t k = has_position ? 0 : 3; k < entries.size(); ++k) m[entries[k]] = 1.0f;
    }
  }
  const auto mean = network_->norm_mean();
  const auto stdv = network_->norm_std();
  for (int w = 0; w < W_; ++w)
    for (int k = 0; k < features::kDim; ++k) {
      float& v = obs_[static_cast<size_t>(w * features::kDim + k)];
      v = (v - mean[static_cast<size_t>(k)]) / stdv[static_cast<size_t>(k)];
    }
}

void DiffusionReconstructor::sample_newest_frame(const features::Canonical& canon, std::array<bool, 2>& contact) {
  if (options_.fixed_noise)
    sampler_.sample_from_noise(obs_, mask_, noise_, out_);
  else
    sampler_.sample(obs_, mask_, out_);

  // Decode the newest frame (into scratch_pose_ and out_global_, model scale).
  const auto mean = network_->norm_mean();
  const auto stdv = network_->norm_std();
  float* newest = out_.data() + static_cast<size_t>(W_ - 1) * features::kDim;
  for (int k = 0; k < features::kDim; ++k)
    newest[k] = newest[k] * stdv[static_cast<size_t>(k)] + mean[static_cast<size_t>(k)];
  features::decode_pose(skeleton_, features::ConstFrame(newest, features::kDim), canon, scratch_pose_, contact);
  forward_kinematics(skeleton_, scratch_pose_, out_global_);
  bend_legs_toward_predicted_ankles(skeleton_, legs_, features::ConstFrame(newest, features::kDim), canon,
                                    options_.leg_position_blend, scratch_pose_, out_global_);
  // Contact with hysteresis, so a value near 0.5 does not flicker between planted and free.
  for (size_t s = 0; s < 2; ++s) {
    const float v = newest[features::kContactOffset + static_cast<int>(s)];
    contact[s] = foot_locked_[s] ? v > options_.contact_off : v > options_.contact_on;
  }
}

void DiffusionReconstructor::filter_body(std::int64_t t_ns) {
  // The network's frame-to-frame jitter (larger on motion styles it has not seen) smoothed on the
  // Hips position and every joint's local rotation. Before the tracked joints are fitted: the
  // head and hands are then put on their trackers as without the filter, so its lag shows only
  // in the untracked joints (bodyd-eval's lag_ms).
  if (!body_filter_.enabled()) return;
  body_filter_.filter(t_ns, scratch_pose_);
  forward_kinematics(skeleton_, scratch_pose_, out_global_);
}

DiffusionReconstructor::JointGoal DiffusionReconstructor::eased_goal(JointEase& ease, JointSource source,
                                                                     const Vec3& base_p, const Quat& base_q, int joint,
                                                                     std::int64_t t_ns, double frame_dt_s) {
  // When a joint's source changes (its tracker is lost or comes back), its goal starts where the
  // joint was last emitted and eases to the new source (offset halving every hand_*_half_life_s,
  // shrinking at most hand_blend_max_speed_m_s), so the joint never jumps (docs/model.md,
  // "Tracked joints").
  const bool tracked = source != JointSource::model;
  const auto j = static_cast<size_t>(joint);
  if (tracked && !ease.ever_tracked) {
    // The joint's first sample since the start: it is where the tracker is from this pose on
    // (easing in from the model's guess made the hands slide in from up to 0.9 m at start-up).
    ease.offset = Vec3::Zero();
    ease.rot_offset = Quat::Identity();
  } else if (source != ease.source && have_last_ && emitted_count_ > 0) {
    // The ease starts where the joint would be now had it kept its last velocity (the last two
    // emitted frames), not where it was: a joint frozen for a frame while the body moves (a run
    // carries it 10-20 cm a frame) is itself a jump.
    const Emitted& last = emitted(emitted_count_ - 1);
    Vec3 start = last.global.positions[j];
    if (emitted_count_ > 1) {
      const Emitted& prev = emitted(emitted_count_ - 2);
      const std::int64_t step_ns = last.t_ns - prev.t_ns;
      if (step_ns > 0 && step_ns <= 2 * frame_dt_ns_ && t_ns - last.t_ns <= 2 * frame_dt_ns_)
        start += (last.global.positions[j] - prev.global.positions[j]) *
                 (static_cast<double>(t_ns - last.t_ns) / static_cast<double>(step_ns));
    }
    ease.offset = start - base_p;
    ease.rot_offset = (last.global.rotations[j] * base_q.conjugate()).normalized();
  } else {
    const double half_life = tracked ? options_.hand_return_half_life_s : options_.hand_loss_half_life_s;
    const double decay = std::exp2(-frame_dt_s / std::max(1e-6, half_life));
    const double n = ease.offset.norm();
    const double shrink = std::min((1.0 - decay) * n, options_.hand_blend_max_speed_m_s * frame_dt_s);
    ease.offset *= n > 0.0 ? (n - shrink) / n : 0.0;
    ease.rot_offset = slerp(Quat::Identity(), ease.rot_offset, decay);
  }
  ease.source = source;
  ease.ever_tracked = ease.ever_tracked || tracked;
  JointGoal goal;
  goal.valid = tracked || ease.offset.squaredNorm() > 1e-10;
  goal.p = base_p + ease.offset;
  goal.q = (ease.rot_offset * base_q).normalized();
  return goal;
}

DiffusionReconstructor::HandGoals DiffusionReconstructor::hand_goals(std::int64_t t_ns, double frame_dt_s,
                                                                     const TrackersNow& trackers, TrackedTargets& targets) {
  // Hand goals: the (filtered) tracker where valid, the model's hand where lost, eased after a
  // loss or a return (eased_goal).
  HandGoals goals;
  for (int side = 0; side < 2; ++side) {
    const Role role = side == 0 ? Role::LeftHand : Role::RightHand;
    const auto r = static_cast<size_t>(role);
    const auto s = static_cast<size_t>(side);
    if (!arms_[side]) continue;
    const auto hand = static_cast<size_t>(arms_[side]->end);
    const bool valid = trackers.valid[r];
    const JointGoal goal = eased_goal(hand_ease_[s], valid ? JointSource::tracker : JointSource::model,
                                      valid ? trackers.p[r] : out_global_.positions[hand],
                                      valid ? trackers.q[r] : out_global_.rotations[hand], arms_[side]->end, t_ns,
                                      frame_dt_s);
    goals.valid[s] = goal.valid;
    goals.p[s] = goal.p;
    goals.q[s] = goal.q;
    targets.hand_valid[s] = valid && options_.exact_tracked_joints;
    targets.hand_m[s] = goals.p[s];
  }
  return goals;
}

void DiffusionReconstructor::fit_tracked_joints(std::int64_t t_ns, double frame_dt_s, const HeadNow& head,
                                                const TrackersNow& trackers, TrackedTargets& targets) {
  // The Head joint on the head tracker, the shoulders moved where a hand is out of reach
  // (body_solver.h). The trackers are the filtered ones: the filter passes clean samples
  // unchanged (its noise gate, one_euro.h), and on noisy ones the body and the tracked joints
  // follow one smooth signal instead of the neck and hips taking up the noise.
  if (!options_.exact_tracked_joints || !upper_body_) return;
  targets.head_valid = head.valid;
  if (head.valid) {
    targets.head_m = head.p;
    targets.head_rotation = head.q;
    // The head correction: the body moves the whole of itself with the Head joint, so what is
    // left of a noisy tracker's noise after the filter would shake every joint (the network's own
    // body is smoother). Where the filter's noise gate is open, the Head joint goes to the
    // network's head plus the low-passed correction instead: the body keeps the network's
    // smoothness and follows the tracker within millimetres. A clean tracker (gain 0) is exact.
    const double gain = filter_.of(Role::Head).position_gain();
    const Vec3 network_head = out_global_.positions[static_cast<size_t>(upper_body_->head)];
    TrackerSample correction;
    correction.t_ns = t_ns;
    correction.valid = true;
    correction.position_m = head.p - network_head;
    const Vec3 smooth = network_head + head_correction_.filter(correction).position_m;
    if (gain > 0.0) targets.head_m += gain * (smooth - head.p);
    targets.head_body_m = targets.head_m;
  } else {
    head_correction_.reset();  // the correction starts over with the head's next sample
  }
  // The reach slack (OneEuroOptions::hand_reach_slack_m): the body does not chase a noisy hand
  // that is just out of reach.
  for (size_t s = 0; s < 2; ++s)
    targets.hand_slack_m[s] = options_.filter.hand_reach_slack_m *
                              filter_.of(s == 0 ? Role::LeftHand : Role::RightHand).position_gain();
  // A hips tracker is not a guess either: the Hips joint goes onto it, eased after a loss or a
  // return as a hand is. Its rotation, and a rotation-only hips tracker, are the network's
  // observations only (turning the Hips to them made the body jerkier or worse on unseen styles,
  // docs/models.md, "The Hips on its tracker").
  const auto h = static_cast<size_t>(Role::Hips);
  const auto hips = static_cast<size_t>(upper_body_->hips);
  const bool tracked = trackers.valid[h] && trackers.has_position[h];
  const JointGoal goal =
      eased_goal(hips_ease_, tracked ? JointSource::tracker : JointSource::model,
                 tracked ? trackers.p[h] : out_global_.positions[hips], out_global_.rotations[hips], upper_body_->hips,
                 t_ns, frame_dt_s);
  targets.hips_valid = goal.valid;
  targets.hips_m = goal.p;
  (void)solve_tracked_body(skeleton_, *upper_body_, options_.body, targets, scratch_pose_, out_global_);
}

std::array<bool, 2> DiffusionReconstructor::fit_tracked_legs(std::int64_t t_ns, double frame_dt_s,
                                                              const TrackersNow& trackers) {
  // A tracked foot is not a guess: the leg reaches it by two-bone IK (the foot turned to the
  // tracker's rotation), and the foot lock leaves it alone. A foot tracked by rotation only keeps
  // the model's ankle and takes the tracker's rotation; the foot lock then holds its toe as
  // usual. A tracked knee is the pole the leg bends toward. Losses and returns ease as a hand's
  // do (eased_goal), the knee's too.
  std::array<bool, 2> placed{};
  if (!options_.exact_tracked_joints) return placed;
  for (int side = 0; side < 2; ++side) {
    const auto s = static_cast<size_t>(side);
    if (!legs_[s]) continue;
    const TwoBoneChain& leg = *legs_[s];
    const auto foot = static_cast<size_t>(leg.end);
    const auto f = static_cast<size_t>(side == 0 ? Role::LeftFoot : Role::RightFoot);
    const auto k = static_cast<size_t>(side == 0 ? Role::LeftKnee : Role::RightKnee);
    const JointSource source = !trackers.valid[f]       ? JointSource::model
                               : trackers.has_position[f] ? JointSource::tracker
                                                          : JointSource::rotation;
    const JointGoal goal =
        eased_goal(foot_ease_[s], source, source == JointSource::tracker ? trackers.p[f] : out_global_.positions[foot],
                   source != JointSource::model ? trackers.q[f] : out_global_.rotations[foot], leg.end, t_ns,
                   frame_dt_s);
    const bool knee_tracked = trackers.valid[k] && trackers.has_position[k];
    const auto knee = static_cast<size_t>(leg.lower);
    const JointGoal knee_goal = eased_goal(knee_ease_[s], knee_tracked ? JointSource::tracker : JointSource::model,
                                           knee_tracked ? trackers.p[k] : out_global_.positions[knee],
                                           out_global_.rotations[knee], leg.lower, t_ns, frame_dt_s);
    if (!goal.valid && !knee_goal.valid) continue;
    TwoBoneTarget target;
    target.position_m = goal.valid ? goal.p : out_global_.positions[foot];
    target.rotation = goal.valid ? goal.q : out_global_.rotations[foot];
    if (knee_goal.valid) target.pole_m = knee_goal.p;
    (void)solve_two_bone_ik(skeleton_, leg, target, scratch_pose_, out_global_);
    placed[s] = goal.valid && source != JointSource::rotation;
  }
  return placed;
}

void DiffusionReconstructor::fit_arms(std::int64_t t_ns, double frame_dt_s, const features::Canonical& canon,
                                      const HandGoals& hands, const TrackersNow& trackers) {
  // Arms by two-bone IK onto the hand goals.
  for (int side = 0; side < 2; ++side) {
    const auto s = static_cast<size_t>(side);
    if (!arms_[side]) continue;
    // An elbow tracker is the arm's pole (eased after a loss or a return, as a hand is): the arm
    // bends in the plane through it.
    const auto e = static_cast<size_t>(side == 0 ? Role::LeftElbow : Role::RightElbow);
    const bool elbow_tracked = options_.exact_tracked_joints && trackers.valid[e] && trackers.has_position[e];
    const auto elbow = static_cast<size_t>(arms_[side]->lower);
    const JointGoal elbow_goal = eased_goal(elbow_ease_[s], elbow_tracked ? JointSource::tracker : JointSource::model,
                                            elbow_tracked ? trackers.p[e] : out_global_.positions[elbow],
                                            out_global_.rotations[elbow], arms_[side]->lower, t_ns, frame_dt_s);
    if (!hands.valid[s] && !elbow_goal.valid) continue;
    const auto hand = static_cast<size_t>(arms_[side]->end);
    TwoBoneTarget target;
    target.position_m = hands.valid[s] ? hands.p[s] : out_global_.positions[hand];
    if (options_.exact_tracked_joints) target.rotation = hands.valid[s] ? hands.q[s] : out_global_.rotations[hand];
    if (elbow_goal.valid) {
      target.pole_m = elbow_goal.p;
    } else {
      // Pole: the elbow as predicted, nudged outward, down and back in the body's frame. A bent
      // elbow keeps its plane; a nearly straight one (whose plane is undefined and would flip
      // between frames) bends the way elbows do.
      const double outward = side == 0 ? 1.0 : -1.0;  // canonical +X is the user's left
      const Vec3 hint = canon.R_world_canon * Vec3(0.5 * outward, -0.5, -1.0).normalized();
      target.pole_m = out_global_.positions[elbow] + options_.elbow_pole_bias_m * hint;
    }
    // The soft reach on a noisy hand (OneEuroOptions::arm_soft_zone_m): the zone grows with the
    // hand filter's noise-gate gain, so a clean hand (gain 0) is reached exactly.
    const Role role = side == 0 ? Role::LeftHand : Role::RightHand;
    target.soft_zone_m = options_.filter.arm_soft_zone_m * filter_.of(role).position_gain();
    (void)solve_two_bone_ik(skeleton_, *arms_[side], target, scratch_pose_, out_global_);
  }
}

void DiffusionReconstructor::remember_emitted(std::int64_t t_ns, const std::array<bool, 2>& contact) {
  // What was emitted (model scale), for the next windows.
  if (emitted_count_ == static_cast<int>(emitted_.size())) {
    emitted_head_ = (emitted_head_ + 1) % static_cast<int>(emitted_.size());
    --emitted_count_;
    emitted_dropped_ = true;
  }
  Emitted& e = emitted_[static_cast<size_t>((emitted_head_ + emitted_count_) % static_cast<int>(emitted_.size()))];
  ++emitted_count_;
  e.t_ns = t_ns;
  for (size_t j = 0; j < e.global.positions.size(); ++j) {
    e.global.positions[j] = out_global_.positions[j];
    e.global.rotations[j] = out_global_.rotations[j];
  }
  features::world_entries(e.global, e.world);
  e.contact = contact;
}

void DiffusionReconstructor::write_user_pose(std::int64_t t_ns, const std::array<bool, 2>& contact,
                                             const std::array<bool, kRoleCount>& tracker_valid, BodyPose& out) const {
  // Back to the user's size.
  const double inv = 1.0 / scale_;
  const size_t nj = static_cast<size_t>(skeleton_.size());
  if (out.pose.local_rotations.size() != nj) out.pose = rest_pose(user_skeleton_);
  if (out.global.positions.size() != nj) out.global = out_global_;
  for (size_t j = 0; j < nj; ++j) {
    out.pose.local_rotations[j] = scratch_pose_.local_rotations[j];
    out.pose.local_translations[j] = scratch_pose_.local_translations[j] * inv;
    out.global.positions[j] = out_global_.positions[j] * inv;
    out.global.rotations[j] = out_global_.rotations[j];
  }
  out.t_ns = t_ns;
  out.foot_contact = contact;
  out.tracker_valid = tracker_valid;
}

}  // namespace bodyd
