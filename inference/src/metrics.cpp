#include "bodyd/inference/metrics.h"

#include <cmath>
#include <limits>
#include <stdexcept>
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
    throw std::invalid_argument("metrics: the skeleton has no joint '" + std::string(name) +
                                "' (the metrics need the 21 body joints of docs/conventions.md)");
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

MetricsAccumulator::MetricsAccumulator(const Skeleton& skeleton) : sets_(joint_sets(skeleton)) {
  pred_hist_.resize(sets_.all.size() * kHistory);
  true_hist_.resize(sets_.all.size() * kHistory);
}

void MetricsAccumulator::begin_clip(double fps) {
  if (!(fps > 0.0) || !std::isfinite(fps))
    throw std::invalid_argument("metrics: fps must be positive, got " + std::to_string(fps));
  fps_ = fps;
  for (Term& t : terms_) {
    t.clip_sum = 0.0;
    t.clip_count = 0;
  }
  clip_frames_ = 0;
  in_clip_ = true;
}

void MetricsAccumulator::add_frame(const GlobalPose& predicted, const GlobalPose& truth) {
  if (!in_clip_) throw std::logic_error("metrics: add_frame() outside begin_clip()/end_clip()");
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
  for (int j : sets_.all)
    terms_[kRot].add(geodesic_angle(predicted.rotations[static_cast<size_t>(j)],
                                    truth.rotations[static_cast<size_t>(j)]) *
                     180.0 / M_PI);

  for (size_t k = 0; k < n; ++k) {
    pred_hist_[slot(f) + k] = predicted.positions[static_cast<size_t>(sets_.all[k])];
    true_hist_[slot(f) + k] = truth.positions[static_cast<size_t>(sets_.all[k])];
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
  }
  if (f >= 3) {
    const double fps3 = fps_ * fps_ * fps_;
    for (size_t k = 0; k < n; ++k) {
      const auto third = [&](const std::vector<Vec3>& h) {
        return (h[slot(f) + k] - 3.0 * h[slot(f - 1) + k] + 3.0 * h[slot(f - 2) + k] - h[slot(f - 3) + k]).norm() *
               fps3;
      };
      terms_[kJitter].add(third(pred_hist_));
      terms_[kTruthJitter].add(third(true_hist_));
    }
  }
  ++clip_frames_;
}

AccuracyMetrics MetricsAccumulator::end_clip() {
  in_clip_ = false;
  AccuracyMetrics m;
  if (clip_frames_ == 0) {
    for (const MetricKey& k : kMetricKeys) m.*k.field = kNaN;
    last_truth_ = {kNaN, kNaN};
    return m;
  }
  m.mpjpe_cm = terms_[kAll].finish(clip_frames_);
  m.upper_pe_cm = terms_[kUpper].finish(clip_frames_);
  m.lower_pe_cm = terms_[kLower].finish(clip_frames_);
  m.hand_pe_cm = terms_[kHands].finish(clip_frames_);
  m.root_pe_cm = terms_[kRoot].finish(clip_frames_);
  m.mpjre_deg = terms_[kRot].finish(clip_frames_);
  m.mpjve_cm_s = terms_[kVel].finish(clip_frames_);
  m.jitter_m_s3 = terms_[kJitter].finish(clip_frames_);
  m.foot_skate_ratio = terms_[kSkate].finish(clip_frames_);
  last_truth_.jitter_m_s3 = terms_[kTruthJitter].finish(clip_frames_);
  last_truth_.foot_skate_ratio = terms_[kTruthSkate].finish(clip_frames_);
  ++clips_;
  frames_ += clip_frames_;
  clip_frames_ = 0;
  return m;
}

AccuracyMetrics MetricsAccumulator::result() const {
  AccuracyMetrics m;
  m.mpjpe_cm = terms_[kAll].mean();
  m.upper_pe_cm = terms_[kUpper].mean();
  m.lower_pe_cm = terms_[kLower].mean();
  m.hand_pe_cm = terms_[kHands].mean();
  m.root_pe_cm = terms_[kRoot].mean();
  m.mpjre_deg = terms_[kRot].mean();
  m.mpjve_cm_s = terms_[kVel].mean();
  m.jitter_m_s3 = terms_[kJitter].mean();
  m.foot_skate_ratio = terms_[kSkate].mean();
  return m;
}

MotionQuality MetricsAccumulator::truth_result() const {
  return {terms_[kTruthJitter].mean(), terms_[kTruthSkate].mean()};
}

}  // namespace bodyd
