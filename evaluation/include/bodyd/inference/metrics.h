// Accuracy metrics of a reconstruction against ground truth, exactly as defined in
// docs/conventions.md ("Accuracy metrics"); docs/evaluation.md repeats the formulas.
//
// Per clip, frame by frame, on global joint positions (metres) and rotations from forward
// kinematics, at the clip's frame rate fps, over the 21 body joints (not joint_Root):
//   mpjpe_cm        mean |p - g| over all 21 joints and frames, x100
//   upper/lower/hand/root_pe_cm  the same over the joint sets (upper 12, lower 9, hands 2, Hips)
//   mpjre_deg       mean geodesic angle between predicted and true global rotations
//   mpjve_cm_s      mean |(p[t+1] - p[t]) - (g[t+1] - g[t])| * fps * 100 over frame pairs
//   jitter_m_s3     mean |p[t+3] - 3 p[t+2] + 3 p[t+1] - p[t]| * fps^3 over frame quadruples
//   foot_skate_ratio  over both Toes joints and frame pairs (t, t+1): the fraction with
//                   y < 0.06 m in both frames and horizontal (x, z) speed > 0.075 m/s
// Beyond docs/conventions.md (issue 10; docs/evaluation.md, "Tracked joints and gaps"):
//   head_pe_cm      mean |p - g| of the Head joint (the head tracker's joint), x100
//   hand_pe_max_cm  the largest |p - g| of a hand over the frames where its tracker is valid
//   gap_hand_jump_cm  the largest frame-to-frame hand jump beyond the true hand's motion,
//                   100 |(p[t+1] - p[t]) - (g[t+1] - g[t])|, over the pairs (t, t+1) where the
//                   hand's tracker is invalid in t or t+1 or was invalid within the last second
//   gap_jerk_m_s3   mean third difference (as jitter) of a hand over the frames in the second
//                   after its tracker came back (the truth's: MotionQuality::gap_jerk_m_s3)
//   lag_ms          how far the untracked joints (the 21 but Head, Hand_L, Hand_R) trail the
//                   truth (issue 18 item 4): the shift k = 0..kMaxLagFrames minimising
//                   E(k) = mean over frames t >= kMaxLagFrames and those joints of |p[t] - g[t-k]|,
//                   refined by the vertex of the parabola through E(k-1), E(k), E(k+1) (E(-1)
//                   compares p[t-1] with g[t], so a lag under half a frame, or a lead, is
//                   resolved too; at k = kMaxLagFrames the shift is not refined), x 1000 / fps.
//                   A clip of fewer than kMaxLagFrames + 1 frames has none.
//   tracked_lag_ms  the same over the tracked joints (Head, Hand_L, Hand_R): what the tracker
//                   filter's smoothing costs in delay (issue 18 item 4)
// hand_pe_max_cm and gap_hand_jump_cm combine over clips as the maximum, the others by frames.
// Clips are combined by their frame count: result = sum(n_clip * clip_metric) / sum(n_clip),
// over the clips where the metric is defined (a 1-frame clip has no velocities, a clip of
// fewer than 4 frames no jitter); a metric no clip defines is NaN.
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/motion/skeleton.h"

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace bodyd {

struct AccuracyMetrics {
  double mpjpe_cm = 0.0;
  double upper_pe_cm = 0.0;
  double lower_pe_cm = 0.0;
  double hand_pe_cm = 0.0;
  double root_pe_cm = 0.0;
  double mpjre_deg = 0.0;
  double mpjve_cm_s = 0.0;
  double jitter_m_s3 = 0.0;
  double foot_skate_ratio = 0.0;
  // Issue 10's additions (not in docs/conventions.md's table; see above).
  double head_pe_cm = 0.0;
  double hand_pe_max_cm = 0.0;
  double gap_hand_jump_cm = 0.0;
  double gap_jerk_m_s3 = 0.0;
  double lag_ms = 0.0;  // issue 18 item 4 (above)
  double tracked_lag_ms = 0.0;
};

// The metric keys of docs/conventions.md, in its order, with their fields.
struct MetricKey {
  std::string_view key;
  double AccuracyMetrics::*field;
};
inline constexpr std::array<MetricKey, 9> kMetricKeys{{
    {"mpjpe_cm", &AccuracyMetrics::mpjpe_cm},
    {"upper_pe_cm", &AccuracyMetrics::upper_pe_cm},
    {"lower_pe_cm", &AccuracyMetrics::lower_pe_cm},
    {"hand_pe_cm", &AccuracyMetrics::hand_pe_cm},
    {"root_pe_cm", &AccuracyMetrics::root_pe_cm},
    {"mpjre_deg", &AccuracyMetrics::mpjre_deg},
    {"mpjve_cm_s", &AccuracyMetrics::mpjve_cm_s},
    {"jitter_m_s3", &AccuracyMetrics::jitter_m_s3},
    {"foot_skate_ratio", &AccuracyMetrics::foot_skate_ratio},
}};
// The keys of the additions, after kMetricKeys in reports.
inline constexpr std::array<MetricKey, 6> kExtraMetricKeys{{
    {"head_pe_cm", &AccuracyMetrics::head_pe_cm},
    {"hand_pe_max_cm", &AccuracyMetrics::hand_pe_max_cm},
    {"gap_hand_jump_cm", &AccuracyMetrics::gap_hand_jump_cm},
    {"gap_jerk_m_s3", &AccuracyMetrics::gap_jerk_m_s3},
    {"lag_ms", &AccuracyMetrics::lag_ms},
    {"tracked_lag_ms", &AccuracyMetrics::tracked_lag_ms},
}};

// The largest shift lag_ms searches, frames.
inline constexpr int kMaxLagFrames = 10;

// Smoothness and foot skating of one motion on its own (reported for ground truth).
struct MotionQuality {
  double jitter_m_s3 = 0.0;
  double foot_skate_ratio = 0.0;
  double gap_jerk_m_s3 = 0.0;  // the true hands' jerk over the frames gap_jerk_m_s3 covers (NaN: no gap)
};

// Contact thresholds of foot_skate_ratio.
inline constexpr double kFootContactHeightM = 0.06;
inline constexpr double kFootSkateSpeedMS = 0.075;

// Skeleton indices of the joint sets of docs/conventions.md, found by name.
struct JointSets {
  std::vector<int> all;    // the 21 body joints: upper then lower
  std::vector<int> upper;  // Spine, Chest, Neck, Head, Shoulder_L/R, UpperArm_L/R, LowerArm_L/R, Hand_L/R
  std::vector<int> lower;  // Hips, UpperLeg_L/R, LowerLeg_L/R, Foot_L/R, Toes_L/R
  std::vector<int> hands;  // Hand_L, Hand_R
  std::vector<int> root;   // Hips
  std::array<int, 2> toes{};  // Toes_L, Toes_R
  int head = -1;              // Head
};
// Throws UserError naming the first body joint the skeleton lacks.
[[nodiscard]] JointSets joint_sets(const Skeleton& skeleton);

// Accumulates the metrics over clips. Per frame: add_frame(predicted, truth), both global
// poses indexed like the skeleton given to the constructor. Keeps only the last four frames
// of positions (of the truth kMaxLagFrames + 1, for lag_ms), so memory does not grow with clip
// length; add_frame does not allocate.
class MetricsAccumulator {
 public:
  explicit MetricsAccumulator(const Skeleton& skeleton);

  // Starts a clip at `fps` frames per second (> 0, else a bug). An unfinished clip is discarded.
  void begin_clip(double fps);
  // `hand_valid`: whether the left and right hand trackers were valid at this frame (for the
  // gap metrics and hand_pe_max_cm); the two-argument form treats both as valid. Only between
  // begin_clip() and end_clip() (else a bug).
  void add_frame(const GlobalPose& predicted, const GlobalPose& truth);
  void add_frame(const GlobalPose& predicted, const GlobalPose& truth, const std::array<bool, 2>& hand_valid);
  // Finishes the clip; its metrics join the totals weighted by its frame count. Returns them
  // (NaN where undefined for this clip). A clip without frames adds nothing.
  AccuracyMetrics end_clip();
  // Ground truth's own jitter and foot skating of the clip last ended.
  [[nodiscard]] const MotionQuality& last_clip_truth() const { return last_truth_; }

  // Frame-weighted means over the finished clips (NaN where no clip defines a metric).
  [[nodiscard]] AccuracyMetrics result() const;
  [[nodiscard]] MotionQuality truth_result() const;
  // jitter_m_s3 joint by joint (the 21 body joints, upper then lower as JointSets::all, by name;
  // their mean is jitter_m_s3), of the reconstruction and of the truth: where the jitter is.
  [[nodiscard]] std::vector<std::pair<std::string, double>> jitter_by_joint() const;
  [[nodiscard]] std::vector<std::pair<std::string, double>> truth_jitter_by_joint() const;
  // The position error joint by joint (cm, the 21 body joints by name as jitter_by_joint; the
  // mean over joints is mpjpe_cm), and its signed height component (cm, the prediction's height
  // minus the truth's, averaged): where the error is, and whether a joint sits too high or too low.
  [[nodiscard]] std::vector<std::pair<std::string, double>> pe_by_joint() const;
  [[nodiscard]] std::vector<std::pair<std::string, double>> height_error_by_joint() const;
  [[nodiscard]] int clips() const { return clips_; }
  [[nodiscard]] std::int64_t frames() const { return frames_; }

 private:
  // Sums and counts of one quantity within a clip, and its weighted total over clips.
  struct Term {
    double clip_sum = 0.0;
    std::int64_t clip_count = 0;
    double total = 0.0;          // sum over clips of n_frames * clip mean
    double total_weight = 0.0;   // sum over clips (defining it) of n_frames
    void add(double v) { clip_sum += v; ++clip_count; }
    double finish(int clip_frames);  // the clip mean (NaN if undefined); folds it into the totals
    [[nodiscard]] double mean() const;
  };
  enum TermId {
    kAll, kUpper, kLower, kHands, kRoot, kRot, kVel, kJitter, kSkate, kTruthJitter, kTruthSkate,
    kHead, kGapJerk, kTruthGapJerk, kLag, kTrackedLag, kTerms
  };
  // The AccuracyMetrics field each term gives: the clip's mean at end_clip(), the run's at result().
  static const std::array<std::pair<double AccuracyMetrics::*, TermId>, 13> kTermFields;
  // lag_ms or tracked_lag_ms of the clip: the slots (within sets_.all) of its joints and the
  // clip's sums of E(k) for k = -1..kMaxLagFrames over `frames` frames.
  struct LagSums {
    std::vector<size_t> slots;
    std::array<double, kMaxLagFrames + 2> error{};
    int frames = 0;
    // The clip's lag (ms) at `fps` (NaN without frames for it).
    [[nodiscard]] double ms(double fps) const;
  };

  JointSets sets_;
  double fps_ = 30.0;
  bool in_clip_ = false;
  int clip_frames_ = 0;
  int clips_ = 0;
  std::int64_t frames_ = 0;
  std::array<Term, kTerms> terms_{};
  MotionQuality last_truth_;
  // Maxima (NaN until defined): per clip and over all clips.
  double clip_hand_max_ = 0.0, clip_gap_jump_ = 0.0, hand_max_ = 0.0, gap_jump_ = 0.0;
  // Per hand: the last clip frame whose tracker was invalid (-1000000: none yet).
  std::array<int, 2> last_invalid_{};
  // Slots of Hand_L, Hand_R within sets_.all.
  std::array<size_t, 2> hand_slot_{};
  // Positions of the body joints (sets_.all order) of the last 4 frames, slot = frame % 4.
  std::vector<Vec3> pred_hist_, true_hist_;
  // The truth's positions of the body joints over the last kMaxLagFrames + 1 frames (slot =
  // frame % (kMaxLagFrames + 1)); lag_ms over the untracked joints, tracked_lag_ms over the others.
  std::vector<Vec3> lag_true_;
  LagSums untracked_lag_, tracked_lag_;
  // jitter_by_joint(): the names of sets_.all and a term per joint (reconstruction, truth).
  std::vector<std::string> joint_names_;
  std::vector<Term> joint_jitter_, truth_joint_jitter_;
  std::vector<Term> joint_pe_, joint_height_error_;  // pe_by_joint(), height_error_by_joint()
  [[nodiscard]] std::vector<std::pair<std::string, double>> named_means(const std::vector<Term>& terms) const;
};

}  // namespace bodyd
