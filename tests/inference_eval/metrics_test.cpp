// Golden values computed by hand from the definitions of docs/conventions.md.
#include "bodyd/inference/metrics.h"

#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace bodyd;

namespace {

const Motion& walk() {
  static const Motion m = read_bvh(test::fixtures() / "walk_60.bvh");
  return m;
}

GlobalPose frame(int f) { return forward_kinematics(walk().skeleton, walk().frames[static_cast<size_t>(f)]); }

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
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("Toes_R"), std::string::npos);
  }
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
