#include "bodyd/inference/metrics.h"

#include "bodyd/base/require.h"
#include "bodyd/base/user_error.h"

#include <cmath>
#include <limits>
#include <string>

namespace bodyd {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr std::string_view kUpperNames[] = {"Spine",      "Chest",      "Neck",       "Head",
                                            "Shoulder_L", "Shoulder_R", "UpperArm_L", "UpperArm_R",
                                            "LowerArm_L", "LowerArm_R", "Hand_L",     "Hand_R"};
constexpr std::string_view kLowerNames[] = {"Hips",       "UpperLeg_L", "UpperLeg_R", "LowerLeg_L", "LowerLeg_R",
                                            "Foot_L",     "Foot_R",     "Toes_L",     "Toes_R"};
constexpr int kHistory = 4;  // frames kept for differences up to the third

int body_joint(const Skeleton& skeleton, std::string_view name) {
  const int j = skeleton.find(name);
  if (j < 0)
    throw UserError("", "metrics: the skeleton has no joint '" + std::string(name) + "'",
                    "the metrics need the 21 body joints of docs/conventions.md (\"Skeleton and joint sets\")");
  return j;
}

}  // namespace

JointSets joint_sets(const Skeleton& skeleton) {
  JointSets s;
  for (std::string_view n : kUpperNames) s.upper.push_back(body_joint(skeleton, n));
  for (std::string_view n : kLowerNames) s.lower.push_back(body_joint(skeleton, n));
  s.all = s.upper;
  s.all.insert(s.all.end(), s.lower.begin(), s.lower.end());
  s.hands = {body_joint(skeleton, "Hand_L"), body_joint(skeleton, "Hand_R")};
  s.root = {body_joint(skeleton, "Hips")};
  s.toes = {body_joint(skeleton, "Toes_L"), body_joint(skeleton, "Toes_R")};
  s.head = body_joint(skeleton, "Head");
  return s;
}

double MetricsAccumulator::Term::finish(int clip_frames) {
  double mean = kNaN;
  if (clip_count > 0) {
    mean = clip_sum / static_cast<double>(clip_count);
    total += static_cast<double>(clip_frames) * mean;
    total_weight += static_cast<double>(clip_frames);
  }
  clip_sum = 0.0;
  clip_count = 0;
  return mean;
}

double MetricsAccumulator::Term::mean() const { return total_weight > 0.0 ? total / total_weight : kNaN; }

namespace {
// max() that treats NaN as "nothing yet".
double max_of(double a, double b) { return std::isnan(a) ? b : (std::isnan(b) ? a : std::max(a, b)); }
constexpr int kNoGap = -1000000;
}  // namespace

MetricsAccumulator::MetricsAccumulator(const Skeleton& skeleton) : sets_(joint_sets(skeleton)) {
  pred_hist_.resize(sets_.all.size() * kHistory);
  true_hist_.resize(sets_.all.size() * kHistory);
  for (size_t h = 0; h < 2; ++h)
    for (size_t k = 0; k < sets_.all.size(); ++k)
      if (sets_.all[k] == sets_.hands[h]) hand_slot_[h] = k;
  hand_max_ = gap_jump_ = kNaN;
  for (size_t k = 0; k < sets_.all.size(); ++k) {
    const bool tracked = sets_.all[k] == sets_.head || sets_.all[k] == sets_.hands[0] || sets_.all[k] == sets_.hands[1];
    (tracked ? tracked_lag_ : untracked_lag_).slots.push_back(k);
  }
  lag_true_.resize(sets_.all.size() * (kMaxLagFrames + 1));
  for (int j : sets_.all) joint_names_.push_back(skeleton.names[static_cast<size_t>(j)]);
  for (auto* terms : {&joint_jitter_, &truth_joint_jitter_, &joint_pe_, &joint_height_error_})
    terms->resize(sets_.all.size());
}

void MetricsAccumulator::begin_clip(double fps) {
  // Clips come from the BVH reader, which refuses frame times outside [0.0001, 1] s.
  BODYD_REQUIRE(fps > 0.0 && std::isfinite(fps), "metrics: fps must be positive, got " + std::to_string(fps));
  fps_ = fps;
  for (auto* terms : {&joint_jitter_, &truth_joint_jitter_, &joint_pe_, &joint_height_error_})
    for (Term& t : *terms) {
      t.clip_sum = 0.0;
      t.clip_count = 0;
    }
  for (Term& t : terms_) {
    t.clip_sum = 0.0;
    t.clip_count = 0;
  }
  clip_frames_ = 0;
  clip_hand_max_ = clip_gap_jump_ = kNaN;
  last_invalid_ = {kNoGap, kNoGap};
  for (LagSums* lag : {&untracked_lag_, &tracked_lag_}) {
    lag->error = {};
    lag->frames = 0;
  }
  in_clip_ = true;
}

void MetricsAccumulator::add_frame(const GlobalPose& predicted, const GlobalPose& truth) {
  add_frame(predicted, truth, {true, true});
}

void MetricsAccumulator::add_frame(const GlobalPose& predicted, const GlobalPose& truth,
                                   const std::array<bool, 2>& hand_valid) {
  BODYD_REQUIRE(in_clip_, "metrics: add_frame() outside begin_clip()/end_clip()");
  const size_t n = sets_.all.size();
  const int f = clip_frames_;
  const auto slot = [n](int frame) { return static_cast<size_t>(frame % kHistory) * n; };

  const auto dist_cm = [&](int j) {
    return 100.0 * (predicted.positions[static_cast<size_t>(j)] - truth.positions[static_cast<size_t>(j)]).norm();
  };
  for (int j : sets_.all) terms_[kAll].add(dist_cm(j));
  for (int j : sets_.upper) terms_[kUpper].add(dist_cm(j));
  for (int j : sets_.lower) terms_[kLower].add(dist_cm(j));
  for (int j : sets_.hands) terms_[kHands].add(dist_cm(j));
  for (int j : sets_.root) terms_[kRoot].add(dist_cm(j));
  terms_[kHead].add(dist_cm(sets_.head));
  for (size_t k = 0; k < n; ++k) {
    const auto j = static_cast<size_t>(sets_.all[k]);
    joint_pe_[k].add(dist_cm(sets_.all[k]));
    joint_height_error_[k].add(100.0 * (predicted.positions[j].y() - truth.positions[j].y()));
  }
  // A pair (f-1, f) is "around a gap" when the hand was invalid in f-1 or f or within the last
  // second; the jerk after a gap is taken at valid frames within a second of the last invalid one.
  const int second = static_cast<int>(std::lround(fps_));
  std::array<int, 2> since_gap{};
  for (size_t h = 0; h < 2; ++h) {
    if (hand_valid[h]) clip_hand_max_ = max_of(clip_hand_max_, dist_cm(sets_.hands[h]));
    const int before = f - last_invalid_[h];  // frames since the last invalid one, up to f-1
    if (!hand_valid[h]) last_invalid_[h] = f;
    since_gap[h] = hand_valid[h] ? before : 0;
  }
  for (int j : sets_.all)
    terms_[kRot].add(geodesic_angle(predicted.rotations[static_cast<size_t>(j)],
                                    truth.rotations[static_cast<size_t>(j)]) *
                     180.0 / M_PI);

  for (size_t k = 0; k < n; ++k) {
    pred_hist_[slot(f) + k] = predicted.positions[static_cast<size_t>(sets_.all[k])];
    true_hist_[slot(f) + k] = truth.positions[static_cast<size_t>(sets_.all[k])];
  }
  // lag_ms and tracked_lag_ms: E(k) of this frame, k = -1..kMaxLagFrames (see metrics.h).
  const auto lag_slot = [n](int frame) { return static_cast<size_t>(frame % (kMaxLagFrames + 1)) * n; };
  for (size_t k = 0; k < n; ++k) lag_true_[lag_slot(f) + k] = true_hist_[slot(f) + k];
  if (f >= kMaxLagFrames) {
    for (LagSums* lag : {&untracked_lag_, &tracked_lag_}) {
      for (int shift = -1; shift <= kMaxLagFrames; ++shift) {
        // shift -1: the output a frame earlier against the truth now.
        const size_t p_at = slot(shift < 0 ? f - 1 : f), g_at = lag_slot(shift < 0 ? f : f - shift);
        double sum = 0.0;
        for (size_t k : lag->slots) sum += (pred_hist_[p_at + k] - lag_true_[g_at + k]).norm();
        lag->error[static_cast<size_t>(shift + 1)] += sum / static_cast<double>(lag->slots.size());
      }
      ++lag->frames;
    }
  }
  if (f >= 1) {
    for (size_t k = 0; k < n; ++k) {
      const Vec3 dp = pred_hist_[slot(f) + k] - pred_hist_[slot(f - 1) + k];
      const Vec3 dg = true_hist_[slot(f) + k] - true_hist_[slot(f - 1) + k];
      terms_[kVel].add((dp - dg).norm() * fps_ * 100.0);
    }
    // Foot skating of a motion: both feet, this frame pair.
    const auto skate = [&](const GlobalPose& pose, const std::vector<Vec3>& hist, Term& term) {
      for (int foot = 0; foot < 2; ++foot) {
        const int j = sets_.toes[static_cast<size_t>(foot)];
        // The toes are in sets_.all; find their slot (lower set, last two entries).
        const size_t k = sets_.upper.size() + sets_.lower.size() - 2 + static_cast<size_t>(foot);
        const Vec3& now = pose.positions[static_cast<size_t>(j)];
        const Vec3& before = hist[slot(f - 1) + k];
        const bool contact = now.y() < kFootContactHeightM && before.y() < kFootContactHeightM;
        const double speed = std::hypot(now.x() - before.x(), now.z() - before.z()) * fps_;
        term.add(contact && speed > kFootSkateSpeedMS ? 1.0 : 0.0);
      }
    };
    skate(predicted, pred_hist_, terms_[kSkate]);
    skate(truth, true_hist_, terms_[kTruthSkate]);
    for (size_t h = 0; h < 2; ++h) {
      // since_gap 0: invalid now; 1: invalid in f-1; <= second: within a second of a gap.
      if (since_gap[h] > second) continue;
      const size_t k = hand_slot_[h];
      const Vec3 dp = pred_hist_[slot(f) + k] - pred_hist_[slot(f - 1) + k];
      const Vec3 dg = true_hist_[slot(f) + k] - true_hist_[slot(f - 1) + k];
      clip_gap_jump_ = max_of(clip_gap_jump_, 100.0 * (dp - dg).norm());
    }
  }
  if (f >= 3) {
    const double fps3 = fps_ * fps_ * fps_;
    for (size_t k = 0; k < n; ++k) {
      const auto third = [&](const std::vector<Vec3>& h) {
        return (h[slot(f) + k] - 3.0 * h[slot(f - 1) + k] + 3.0 * h[slot(f - 2) + k] - h[slot(f - 3) + k]).norm() *
               fps3;
      };
      const double pred = third(pred_hist_), true_ = third(true_hist_);
      terms_[kJitter].add(pred);
      terms_[kTruthJitter].add(true_);
      joint_jitter_[k].add(pred);
      truth_joint_jitter_[k].add(true_);
    }
    for (size_t h = 0; h < 2; ++h) {
      if (since_gap[h] < 1 || since_gap[h] > second) continue;
      const size_t k = hand_slot_[h];
      const auto third = [&](const std::vector<Vec3>& hist) {
        return (hist[slot(f) + k] - 3.0 * hist[slot(f - 1) + k] + 3.0 * hist[slot(f - 2) + k] - hist[slot(f - 3) + k])
                   .norm() * fps3;
      };
      terms_[kGapJerk].add(third(pred_hist_));
      terms_[kTruthGapJerk].add(third(true_hist_));
    }
  }
  ++clip_frames_;
}

double MetricsAccumulator::LagSums::ms(double fps) const {
  if (frames == 0) return kNaN;
  // E(shift) is error[shift + 1] / frames; the common factor does not move the vertex.
  const auto e = [&](int shift) { return error[static_cast<size_t>(shift + 1)]; };
  int best = 0;
  for (int shift = 1; shift <= kMaxLagFrames; ++shift)
    if (e(shift) < e(best)) best = shift;
  double lag = best;
  if (best < kMaxLagFrames) {
    const double curvature = e(best - 1) - 2.0 * e(best) + e(best + 1);
    if (curvature > 0.0) lag += 0.5 * (e(best - 1) - e(best + 1)) / curvature;
  }
  return 1000.0 * lag / fps;
}

const std::array<std::pair<double AccuracyMetrics::*, MetricsAccumulator::TermId>, 13>
    MetricsAccumulator::kTermFields{{{&AccuracyMetrics::mpjpe_cm, kAll},
                                     {&AccuracyMetrics::upper_pe_cm, kUpper},
                                     {&AccuracyMetrics::lower_pe_cm, kLower},
                                     {&AccuracyMetrics::hand_pe_cm, kHands},
                                     {&AccuracyMetrics::root_pe_cm, kRoot},
                                     {&AccuracyMetrics::mpjre_deg, kRot},
                                     {&AccuracyMetrics::mpjve_cm_s, kVel},
                                     {&AccuracyMetrics::jitter_m_s3, kJitter},
                                     {&AccuracyMetrics::foot_skate_ratio, kSkate},
                                     {&AccuracyMetrics::head_pe_cm, kHead},
                                     {&AccuracyMetrics::gap_jerk_m_s3, kGapJerk},
                                     {&AccuracyMetrics::lag_ms, kLag},
                                     {&AccuracyMetrics::tracked_lag_ms, kTrackedLag}}};

AccuracyMetrics MetricsAccumulator::end_clip() {
  in_clip_ = false;
  AccuracyMetrics m;
  if (clip_frames_ == 0) {
    for (const MetricKey& k : kMetricKeys) m.*k.field = kNaN;
    m.lag_ms = m.tracked_lag_ms = kNaN;
    last_truth_ = {kNaN, kNaN, kNaN};
    return m;
  }
  if (const double lag = untracked_lag_.ms(fps_); !std::isnan(lag)) terms_[kLag].add(lag);
  if (const double lag = tracked_lag_.ms(fps_); !std::isnan(lag)) terms_[kTrackedLag].add(lag);
  for (const auto& [field, term] : kTermFields) m.*field = terms_[term].finish(clip_frames_);
  for (auto* terms : {&joint_jitter_, &truth_joint_jitter_, &joint_pe_, &joint_height_error_})
    for (Term& t : *terms) (void)t.finish(clip_frames_);
  last_truth_.jitter_m_s3 = terms_[kTruthJitter].finish(clip_frames_);
  last_truth_.foot_skate_ratio = terms_[kTruthSkate].finish(clip_frames_);
  last_truth_.gap_jerk_m_s3 = terms_[kTruthGapJerk].finish(clip_frames_);
  m.hand_pe_max_cm = clip_hand_max_;
  m.gap_hand_jump_cm = clip_gap_jump_;
  hand_max_ = max_of(hand_max_, clip_hand_max_);
  gap_jump_ = max_of(gap_jump_, clip_gap_jump_);
  ++clips_;
  frames_ += clip_frames_;
  clip_frames_ = 0;
  return m;
}

AccuracyMetrics MetricsAccumulator::result() const {
  AccuracyMetrics m;
  for (const auto& [field, term] : kTermFields) m.*field = terms_[term].mean();
  m.hand_pe_max_cm = hand_max_;
  m.gap_hand_jump_cm = gap_jump_;
  return m;
}

MotionQuality MetricsAccumulator::truth_result() const {
  return {terms_[kTruthJitter].mean(), terms_[kTruthSkate].mean(), terms_[kTruthGapJerk].mean()};
}

std::vector<std::pair<std::string, double>> MetricsAccumulator::named_means(const std::vector<Term>& terms) const {
  std::vector<std::pair<std::string, double>> out;
  for (size_t k = 0; k < joint_names_.size(); ++k) out.emplace_back(joint_names_[k], terms[k].mean());
  return out;
}

std::vector<std::pair<std::string, double>> MetricsAccumulator::jitter_by_joint() const {
  return named_means(joint_jitter_);
}

std::vector<std::pair<std::string, double>> MetricsAccumulator::truth_jitter_by_joint() const {
  return named_means(truth_joint_jitter_);
}

std::vector<std::pair<std::string, double>> MetricsAccumulator::pe_by_joint() const { return named_means(joint_pe_); }

std::vector<std::pair<std::string, double>> MetricsAccumulator::height_error_by_joint() const {
  return named_means(joint_height_error_);
}

}  // namespace bodyd
