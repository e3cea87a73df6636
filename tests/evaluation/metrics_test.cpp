// Golden values computed by hand from the definitions of docs/conventions.md.
#include "bodyd/inference/metrics.h"

#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>

using namespace bodyd;

namespace {

const Motion& walk() {
  static const Motion m = read_bvh(test::fixtures() / "walk_60.bvh");
  return m;
}

GlobalPose frame(int f) { return forward_kinematics(walk().skeleton, walk().frames[static_cast<size_t>(f)]); }

// One clip of the walk at 30 fps, predicted by `predict(f)`: its metrics.
AccuracyMetrics walk_clip(MetricsAccumulator& acc, const std::function<GlobalPose(int)>& predict) {
  acc.begin_clip(30.0);
  for (int f = 0; f < walk().frame_count(); ++f) acc.add_frame(predict(f), frame(f));
  return acc.end_clip();
}

// `pred` with the head's and hands' positions of `from` (the tracked joints).
GlobalPose with_tracked_of(GlobalPose pred, const GlobalPose& from) {
  const JointSets sets = joint_sets(walk().skeleton);
  for (int j : {sets.head, sets.hands[0], sets.hands[1]})
    pred.positions[static_cast<size_t>(j)] = from.positions[static_cast<size_t>(j)];
  return pred;
}

// A pose with every joint at `p` (identity rotations).
GlobalPose all_at(const Vec3& p) {
  GlobalPose g;
  g.positions.assign(static_cast<size_t>(walk().skeleton.size()), p);
  g.rotations.assign(static_cast<size_t>(walk().skeleton.size()), Quat::Identity());
  return g;
}

}  // namespace

TEST(Metrics, JointSetsAreThoseOfTheConventions) {
  const JointSets s = joint_sets(walk().skeleton);
  EXPECT_EQ(s.all.size(), 21u);
  EXPECT_EQ(s.upper.size(), 12u);
  EXPECT_EQ(s.lower.size(), 9u);
  EXPECT_EQ(s.hands.size(), 2u);
  ASSERT_EQ(s.root.size(), 1u);
  EXPECT_EQ(walk().skeleton.names[static_cast<size_t>(s.root[0])], "Hips");
  for (int j : s.all) EXPECT_NE(walk().skeleton.names[static_cast<size_t>(j)], "joint_Root");
  Skeleton bad = walk().skeleton;
  bad.names[static_cast<size_t>(bad.find("Toes_R"))] = "Claw";
  try {
    (void)joint_sets(bad);
    FAIL();
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("Toes_R"), std::string::npos);
  }
}

TEST(MetricsDeathTest, AFrameOutsideAClipOrAClipAtNoFpsIsABug) {
  // Clips come from the BVH reader (frame times in [0.0001, 1] s): only bodyd's code can break these.
  MetricsAccumulator acc(walk().skeleton);
  EXPECT_DEATH(acc.add_frame(frame(0), frame(0)), "bug: metrics: add_frame\\(\\) outside begin_clip");
  EXPECT_DEATH(acc.begin_clip(0.0), "bug: metrics: fps must be positive");
}

TEST(Metrics, ConstantOffsetOfTwoCentimetres) {
  MetricsAccumulator acc(walk().skeleton);
  acc.begin_clip(30.0);
  const Vec3 offset = Vec3(1.0, 2.0, -2.0).normalized() * 0.02;
  for (int f = 0; f < walk().frame_count(); ++f) {
    const GlobalPose truth = frame(f);
    GlobalPose pred = truth;
    for (Vec3& p : pred.positions) p += offset;
    acc.add_frame(pred, truth);
  }
  const AccuracyMetrics clip = acc.end_clip();
  for (double v : {clip.mpjpe_cm, clip.upper_pe_cm, clip.lower_pe_cm, clip.hand_pe_cm, clip.root_pe_cm})
    EXPECT_NEAR(v, 2.0, 1e-12);
  EXPECT_NEAR(clip.mpjre_deg, 0.0, 1e-5);
  EXPECT_NEAR(clip.mpjve_cm_s, 0.0, 1e-9);
  const AccuracyMetrics all = acc.result();
  EXPECT_NEAR(all.mpjpe_cm, 2.0, 1e-12);
  EXPECT_EQ(acc.clips(), 1);
  EXPECT_EQ(acc.frames(), 60);
  // The prediction moves exactly like the truth, so their jitter and skating agree.
  EXPECT_NEAR(all.jitter_m_s3, acc.truth_result().jitter_m_s3, 1e-9);
}

TEST(Metrics, PerSetErrorsAndGlobalRotationAngle) {
  MetricsAccumulator acc(walk().skeleton);
  const JointSets s = joint_sets(walk().skeleton);
  acc.begin_clip(30.0);
  const GlobalPose truth = frame(0);
  GlobalPose pred = truth;
  // Only the hands are off, by 3 cm and by a 10 degree turn.
  for (int j : s.hands) {
    pred.positions[static_cast<size_t>(j)] += Vec3(0, 0.03, 0);
    pred.rotations[static_cast<size_t>(j)] =
        Quat(Eigen::AngleAxisd(10.0 * M_PI / 180.0, Vec3(0.2, 0.9, 0.1).normalized())) *
        truth.rotations[static_cast<size_t>(j)];
  }
  acc.add_frame(pred, truth);
  const AccuracyMetrics m = acc.end_clip();
  EXPECT_NEAR(m.hand_pe_cm, 3.0, 1e-9);
  EXPECT_NEAR(m.upper_pe_cm, 3.0 * 2 / 12, 1e-9);
  EXPECT_NEAR(m.lower_pe_cm, 0.0, 1e-12);
  EXPECT_NEAR(m.root_pe_cm, 0.0, 1e-12);
  EXPECT_NEAR(m.mpjpe_cm, 3.0 * 2 / 21, 1e-9);
  EXPECT_NEAR(m.mpjre_deg, 10.0 * 2 / 21, 1e-6);
  // One frame: no velocity, no third difference, no frame pair for skating.
  EXPECT_TRUE(std::isnan(m.mpjve_cm_s));
  EXPECT_TRUE(std::isnan(m.jitter_m_s3));
  EXPECT_TRUE(std::isnan(m.foot_skate_ratio));
}

TEST(Metrics, VelocityErrorAndJitterOfKnownTrajectories) {
  // Prediction: every joint on x(t) = c t^3 (third derivative 6c, and the third difference of a
  // cubic is exactly 6 c dt^3, so jitter = 6c). Truth: still. Velocity error per pair:
  // |x(t+dt) - x(t)| * fps.
  const double fps = 30.0, dt = 1.0 / fps, c = 0.5;
  MetricsAccumulator acc(walk().skeleton);
  acc.begin_clip(fps);
  const int n = 10;
  double vel_sum_cm_s = 0.0;
  for (int f = 0; f < n; ++f) {
    const double t = f * dt;
    acc.add_frame(all_at(Vec3(c * t * t * t, 1.0, 0.0)), all_at(Vec3(0, 1.0, 0)));
    if (f > 0) {
      const double t0 = (f - 1) * dt;
      vel_sum_cm_s += (c * t * t * t - c * t0 * t0 * t0) * fps * 100.0;
    }
  }
  const AccuracyMetrics m = acc.end_clip();
  EXPECT_NEAR(m.jitter_m_s3, 6.0 * c, 1e-6);
  EXPECT_NEAR(m.mpjve_cm_s, vel_sum_cm_s / (n - 1), 1e-9);
  EXPECT_NEAR(acc.last_clip_truth().jitter_m_s3, 0.0, 1e-12);
  EXPECT_NEAR(acc.truth_result().jitter_m_s3, 0.0, 1e-12);
}

TEST(Metrics, FootSkateRatioOfASlidingFoot) {
  // 11 frames = 10 pairs per foot, 20 in all. Left toes at 2 cm, sliding at 0.1 m/s for the first
  // 5 pairs, then at 0.05 m/s (under 7.5 cm/s) for 5 pairs: 5 skating pairs. Right toes slide fast
  // but at 10 cm height (no contact). Ratio 5 / 20.
  const Skeleton& sk = walk().skeleton;
  const auto toes_l = static_cast<size_t>(sk.find("Toes_L")), toes_r = static_cast<size_t>(sk.find("Toes_R"));
  const double fps = 30.0;
  MetricsAccumulator acc(sk);
  acc.begin_clip(fps);
  double xl = 0.0, xr = 0.0;
  for (int f = 0; f <= 10; ++f) {
    GlobalPose g = all_at(Vec3(0, 1, 0));
    g.positions[toes_l] = Vec3(0.0, 0.02, xl);
    g.positions[toes_r] = Vec3(xr, 0.10, 0.0);
    acc.add_frame(g, g);
    xl += (f < 5 ? 0.1 : 0.05) / fps;
    xr += 1.0 / fps;
  }
  const AccuracyMetrics m = acc.end_clip();
  EXPECT_NEAR(m.foot_skate_ratio, 0.25, 1e-12);
  EXPECT_NEAR(acc.last_clip_truth().foot_skate_ratio, 0.25, 1e-12);

  // A foot that lifts off: 5.9 cm and 6.1 cm are contact and no contact.
  acc.begin_clip(fps);
  for (int f = 0; f < 3; ++f) {
    GlobalPose g = all_at(Vec3(0, 1, 0));
    g.positions[toes_l] = Vec3(f * 0.01, f == 2 ? 0.061 : 0.059, 0.0);  // 0.3 m/s
    g.positions[toes_r] = Vec3(0, 0, 0);
    acc.add_frame(g, g);
  }
  EXPECT_NEAR(acc.end_clip().foot_skate_ratio, 1.0 / 4.0, 1e-12);
}

TEST(Metrics, ClipsCombineWeightedByFrameCount) {
  MetricsAccumulator acc(walk().skeleton);
  const auto clip = [&](int frames, double err_m) {
    acc.begin_clip(30.0);
    for (int f = 0; f < frames; ++f) acc.add_frame(all_at(Vec3(err_m, 1, 0)), all_at(Vec3(0, 1, 0)));
    return acc.end_clip();
  };
  EXPECT_NEAR(clip(10, 0.01).mpjpe_cm, 1.0, 1e-12);
  EXPECT_NEAR(clip(30, 0.03).mpjpe_cm, 3.0, 1e-12);
  EXPECT_NEAR(acc.result().mpjpe_cm, (10 * 1.0 + 30 * 3.0) / 40.0, 1e-12);
  // A 1-frame clip counts for positions but defines no velocity: mpjve stays that of the others.
  clip(1, 0.05);
  EXPECT_NEAR(acc.result().mpjpe_cm, (10 * 1.0 + 30 * 3.0 + 5.0) / 41.0, 1e-12);
  EXPECT_NEAR(acc.result().mpjve_cm_s, 0.0, 1e-12);
  EXPECT_EQ(acc.frames(), 41);
  EXPECT_EQ(acc.clips(), 3);
  // An empty clip adds nothing.
  acc.begin_clip(30.0);
  EXPECT_TRUE(std::isnan(acc.end_clip().mpjpe_cm));
  EXPECT_EQ(acc.clips(), 3);
}

TEST(Metrics, HeadErrorHandMaximumAndTheGapMetrics) {
  // 60 frames at 30 fps; truth still (every joint at (0, 1, 0)). The prediction: the Head 1 cm
  // off throughout; the left hand 0.5 cm off while tracked, and its tracker lost for frames
  // 10..14 during which the hand is 20 cm off (a jump of 19.5 cm into the gap at 9 -> 10 and back
  // at 14 -> 15). After the gap (frames 15..45) the hand follows x = c (t - t15)^3 from frame 15
  // on at 0.5 cm off, so its third difference is 6c dt^3 exactly once four frames are on the
  // cubic (frames 18..45); frames 15..17 mix the gap in (computed below).
  const Skeleton& sk = walk().skeleton;
  const auto head = static_cast<size_t>(sk.find("Head")), hand = static_cast<size_t>(sk.find("Hand_L"));
  const double fps = 30.0, dt = 1.0 / fps, c = 0.2;
  MetricsAccumulator acc(sk);
  acc.begin_clip(fps);
  std::vector<Vec3> hand_path;
  for (int f = 0; f < 60; ++f) {
    GlobalPose truth = all_at(Vec3(0, 1, 0)), pred = truth;
    pred.positions[head] += Vec3(0, 0, 0.01);
    const bool lost = f >= 10 && f <= 14;
    Vec3 h = Vec3(0, 1, 0.005);
    if (lost) h = Vec3(0, 1, 0.2);
    if (f >= 15) {
      const double t = (f - 15) * dt;
      h.x() = c * t * t * t;
    }
    pred.positions[hand] = h;
    hand_path.push_back(h);
    acc.add_frame(pred, truth, {!lost, true});
  }
  const AccuracyMetrics m = acc.end_clip();
  EXPECT_NEAR(m.head_pe_cm, 1.0, 1e-9);
  // The largest tracked hand error: the cubic at frame 59 is past the second after the gap but
  // still counts (tracked); its distance from (0, 1, 0).
  const double t59 = 44 * dt;
  EXPECT_NEAR(m.hand_pe_max_cm, 100.0 * std::hypot(c * t59 * t59 * t59, 0.005), 1e-9);
  // Jumps: into the gap 19.5 cm, out of it 19.5 cm (plus the cubic's first step, 0 at t = 0).
  EXPECT_NEAR(m.gap_hand_jump_cm, 19.5, 1e-9);
  // Jerk after the gap: valid frames 15..45 (within 30 frames of frame 14) and f >= 3.
  double sum = 0.0;
  int n = 0;
  for (int f = 15; f <= 44; ++f) {
    const auto u = static_cast<size_t>(f);
    sum += (hand_path[u] - 3.0 * hand_path[u - 1] + 3.0 * hand_path[u - 2] - hand_path[u - 3]).norm() * fps * fps * fps;
    ++n;
  }
  EXPECT_NEAR(m.gap_jerk_m_s3, sum / n, 1e-6 * sum / n);
  EXPECT_NEAR(acc.last_clip_truth().gap_jerk_m_s3, 0.0, 1e-12);

  // No gap: the gap metrics are undefined (NaN), the others as before.
  acc.begin_clip(fps);
  for (int f = 0; f < 10; ++f) acc.add_frame(all_at(Vec3(0, 1, 0)), all_at(Vec3(0, 1, 0)), {true, true});
  const AccuracyMetrics none = acc.end_clip();
  EXPECT_TRUE(std::isnan(none.gap_hand_jump_cm));
  EXPECT_TRUE(std::isnan(none.gap_jerk_m_s3));
  EXPECT_NEAR(none.hand_pe_max_cm, 0.0, 1e-12);
  // Over both clips the maxima are kept.
  EXPECT_NEAR(acc.result().gap_hand_jump_cm, 19.5, 1e-9);
}

// lag_ms (issue 18 item 4): a copy of the truth delayed by 3 frames trails it by 100 ms at 30
// fps (the tracked joints, on time here, do not count); the truth itself by 0; clips combine by
// frames; a clip too short for the search has none.
TEST(Metrics, LagOfADelayedCopyOfTheTruth) {
  MetricsAccumulator acc(walk().skeleton);
  const AccuracyMetrics delayed =
      walk_clip(acc, [](int f) { return with_tracked_of(frame(std::max(0, f - 3)), frame(f)); });
  EXPECT_NEAR(delayed.lag_ms, 100.0, 5.0);
  EXPECT_NEAR(delayed.tracked_lag_ms, 0.0, 1e-9);  // the tracked joints were on time
  EXPECT_NEAR(walk_clip(acc, frame).lag_ms, 0.0, 1e-9);
  // Two clips of 60 frames: the mean of 100 and 0.
  EXPECT_NEAR(acc.result().lag_ms, 50.0, 2.5);
  // A lead reads as a negative lag, within a frame.
  const double lead = walk_clip(acc, [](int f) {
                        GlobalPose pred = frame(f), next = frame(std::min(f + 1, walk().frame_count() - 1));
                        for (size_t j = 0; j < pred.positions.size(); ++j)
                          pred.positions[j] = 0.5 * (pred.positions[j] + next.positions[j]);
                        return pred;
                      }).lag_ms;
  EXPECT_LT(lead, -5.0);
  EXPECT_GT(lead, -33.4);
  acc.begin_clip(30.0);
  for (int f = 0; f < kMaxLagFrames; ++f) acc.add_frame(frame(f), frame(f));
  const AccuracyMetrics short_clip = acc.end_clip();
  EXPECT_TRUE(std::isnan(short_clip.lag_ms));
  EXPECT_TRUE(std::isnan(short_clip.tracked_lag_ms));
}

// tracked_lag_ms: the head and hands alone, 2 frames late (what a tracker filter's delay does),
// trail by 66.7 ms while the rest of the body, on time, reads 0.
TEST(Metrics, TrackedLagIsTheHeadAndHandsAlone) {
  MetricsAccumulator acc(walk().skeleton);
  const AccuracyMetrics m = walk_clip(acc, [](int f) { return with_tracked_of(frame(f), frame(std::max(0, f - 2))); });
  EXPECT_NEAR(m.tracked_lag_ms, 66.7, 4.0);
  EXPECT_NEAR(m.lag_ms, 0.0, 1e-9);
  EXPECT_NEAR(acc.result().tracked_lag_ms, m.tracked_lag_ms, 1e-9);
}

// pe_by_joint and height_error_by_joint: one knee 3 cm forward and 4 cm low in one clip, the
// other clip exact; each clip counts by its frames (as mpjpe_cm), every other joint is 0, and
// the joints' mean of pe_by_joint is mpjpe_cm.
namespace {
// Two clips, the walk's frames then its first 20, each frame the truth changed by `change(clip,
// frame, pose)` as the reconstruction.
using JointValues = std::vector<std::pair<std::string, double>>;

// Whether both list the 21 joints of the walk, in one order.
::testing::AssertionResult same_21_joints(const JointValues& a, const JointValues& b) {
  if (a.size() != 21 || b.size() != 21) return ::testing::AssertionFailure() << a.size() << " and " << b.size() << " joints";
  for (size_t k = 0; k < a.size(); ++k)
    if (a[k].first != b[k].first) return ::testing::AssertionFailure() << a[k].first << " vs " << b[k].first;
  return ::testing::AssertionSuccess();
}

// The mean over the joints (the metric's value: every joint weighs the same).
double joint_mean(const JointValues& values) {
  double sum = 0.0;
  for (const auto& [joint, value] : values) sum += value;
  return sum / static_cast<double>(values.size());
}

void two_clips(MetricsAccumulator& acc, const std::function<void(int, int, GlobalPose&)>& change) {
  const int lengths[2] = {walk().frame_count(), 20};
  for (int clip = 0; clip < 2; ++clip) {
    acc.begin_clip(30.0);
    for (int f = 0; f < lengths[clip]; ++f) {
      const GlobalPose truth = frame(f);
      GlobalPose pred = truth;
      change(clip, f, pred);
      acc.add_frame(pred, truth);
    }
    (void)acc.end_clip();
  }
}
}  // namespace

TEST(Metrics, PositionErrorByJointFindsTheMovedJointAndItsHeight) {
  MetricsAccumulator acc(walk().skeleton);
  const auto knee = static_cast<size_t>(walk().skeleton.find("LowerLeg_R"));
  const int moved_frames = walk().frame_count(), exact_frames = 20;
  two_clips(acc, [&](int clip, int, GlobalPose& pred) {
    if (clip == 0) pred.positions[knee] += Vec3(0.0, -0.04, 0.03);
  });
  const double share = static_cast<double>(moved_frames) / (moved_frames + exact_frames);
  const auto pe = acc.pe_by_joint(), height = acc.height_error_by_joint();
  ASSERT_TRUE(same_21_joints(pe, height));
  for (size_t k = 0; k < pe.size(); ++k) {
    const bool moved = pe[k].first == "LowerLeg_R";
    EXPECT_NEAR(pe[k].second, moved ? 5.0 * share : 0.0, 1e-9) << pe[k].first;
    EXPECT_NEAR(height[k].second, moved ? -4.0 * share : 0.0, 1e-9) << pe[k].first;
  }
  EXPECT_NEAR(joint_mean(pe), acc.result().mpjpe_cm, 1e-9);
}

// jitter_by_joint: one elbow shaken by +-1 cm alternately (third difference 8 cm, jerk 8 cm x
// 30^3 = 2160 m/s^3 at every quadruple) shows up at that joint alone; the joints' mean is
// jitter_m_s3, over two clips of different lengths too; the truth's by joint is its own.
TEST(Metrics, JitterByJointFindsTheShakenJoint) {
  MetricsAccumulator acc(walk().skeleton);
  const auto elbow = static_cast<size_t>(walk().skeleton.find("LowerArm_L"));
  two_clips(acc, [&](int, int f, GlobalPose& pred) { pred.positions[elbow].y() += (f % 2 == 0 ? 0.01 : -0.01); });
  const auto pred = acc.jitter_by_joint(), truth = acc.truth_jitter_by_joint();
  ASSERT_TRUE(same_21_joints(pred, truth));
  for (size_t k = 0; k < pred.size(); ++k) {
    // The shaken elbow's is 2160 give or take the true elbow's own (the triangle inequality per
    // quadruple); every other joint is the truth's.
    if (pred[k].first == "LowerArm_L") {
      EXPECT_LT(truth[k].second, 500.0);
      EXPECT_NEAR(pred[k].second, 2160.0, truth[k].second + 1e-6);
    } else {
      EXPECT_NEAR(pred[k].second, truth[k].second, 1e-9) << pred[k].first;
    }
  }
  EXPECT_NEAR(joint_mean(pred), acc.result().jitter_m_s3, 1e-9);
  EXPECT_NEAR(joint_mean(truth), acc.truth_result().jitter_m_s3, 1e-9);
}
