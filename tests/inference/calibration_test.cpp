// Height calibration from the head tracker (calibration.h) and the tracker filter (one_euro.h).
#include "bodyd/inference/calibration.h"
#include "bodyd/inference/ik.h"
#include "bodyd/inference/one_euro.h"

#include "bodyd/motion/bvh.h"

#include "../test_paths.h"
#include "bodyd/test/alloc_counter.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace bodyd;

namespace {

TrackerSample head_at(double t_s, const Vec3& p, bool valid = true) {
  TrackerSample s;
  s.t_ns = static_cast<std::int64_t>(std::llround(t_s * 1e9));
  s.role = Role::Head;
  s.valid = valid;
  s.position_m = p;
  s.rotation = Quat::Identity();
  return s;
}

}  // namespace

TEST(StandingHeight, ReportsTheFirstStillHalfSecondOnceWithTheStanceCorrection) {
  // 90 Hz: walking for 0.5 s, then standing at 1.60 m with +-5 mm sway and 1 cm/s drift for 2 s.
  const StandingHeightOptions o;
  StandingHeightDetector d(o);
  std::optional<StandingHeight> found;
  double sum = 0.0;
  int n = 0, reports = 0;
  for (int k = 0; k < 225; ++k) {
    const double t = k / 90.0;
    const Vec3 p = k < 45 ? Vec3(0.8 * t, 1.45, 0.0) : Vec3(0.4 + 0.01 * t, 1.60 + 0.005 * std::sin(7.0 * t), 0.0);
    if (k >= 45 && k <= 90) {  // the first half second of standing, both ends included
      sum += p.y();
      ++n;
    }
    if (const auto h = d.push(head_at(t, p))) {
      ++reports;
      found = h;
    }
    // Other roles and invalid samples are ignored.
    TrackerSample hand = head_at(t, Vec3(5, 0, 0));
    hand.role = Role::LeftHand;
    EXPECT_FALSE(d.push(hand));
  }
  ASSERT_TRUE(found);
  EXPECT_EQ(reports, 1);
  EXPECT_FALSE(found->fallback);
  // Complete half a second after the first standing sample (t = 0.5 s, 15 cm above the last step).
  EXPECT_EQ(found->t_ns, head_at(1.0, Vec3::Zero()).t_ns);
  EXPECT_NEAR(found->measured_m, sum / n, 1e-12);
  EXPECT_NEAR(found->head_height_m, sum / n / 0.987, 1e-12);
  EXPECT_NEAR(standing_height_from_head(1.5, o), 1.5 / 0.987, 1e-12);
  EXPECT_TRUE(d.done());
  d.reset();
  EXPECT_FALSE(d.done());
  EXPECT_FALSE(d.result());
}

TEST(StandingHeight, SittingGivesUpAWalkGetsTheFallbackAndGapsAreIgnored) {
  const StandingHeightOptions o;  // fallback after 1.5 s: the 90th percentile
  StandingHeightDetector sitting(o), walking(o), swaying(o);
  std::optional<StandingHeight> walk, sway;
  for (int k = 0; k < 450; ++k) {
    const double t = k / 90.0;
    EXPECT_FALSE(sitting.push(head_at(t, Vec3(0, 0.85, 0))));  // still, but below min_height_m
    // 1 m/s with the head bobbing 3 cm at 2 steps a second: never still.
    if (auto h = walking.push(head_at(t, Vec3(t, 1.55 + 0.03 * std::sin(4.0 * M_PI * t), 0)))) walk = h;
    // In place but bouncing 8 cm up and down once a second: any half second spans at least 4 cm.
    if (auto h = swaying.push(head_at(t, Vec3(0, 1.60 + 0.04 * std::sin(2.0 * M_PI * t), 0)))) sway = h;
  }
  EXPECT_TRUE(sitting.done());
  EXPECT_FALSE(sitting.result());
  ASSERT_TRUE(walk);
  EXPECT_TRUE(walk->fallback);
  EXPECT_EQ(walk->t_ns, head_at(1.5, Vec3::Zero()).t_ns);
  // The 90th percentile of 1.55 + 0.03 sin over three whole periods: sin exceeds v for a fraction
  // (pi - 2 asin v) / (2 pi) of the time, 10% at v = sin(0.4 pi). Within a sample step (1.3 mm)
  // and the 1 mm bin.
  EXPECT_NEAR(walk->measured_m, 1.55 + 0.03 * std::sin(0.4 * M_PI), 0.003);
  EXPECT_NEAR(walk->head_height_m, walk->measured_m / o.stance_ratio, 1e-12);
  ASSERT_TRUE(sway);
  EXPECT_TRUE(sway->fallback);

  // Without the fallback a walk never gives a height.
  StandingHeightOptions no_fallback = o;
  no_fallback.fallback_after_s = 0.0;
  StandingHeightDetector never(no_fallback);
  for (int k = 0; k < 900; ++k) EXPECT_FALSE(never.push(head_at(k / 90.0, Vec3(k / 90.0, 1.55, 0))));
  EXPECT_FALSE(never.done());

  // A gap (invalid samples) neither starts nor ends a stretch.
  StandingHeightDetector gap;
  std::optional<StandingHeight> h;
  for (int k = 0; k <= 45 && !h; ++k) h = gap.push(head_at(k / 90.0, Vec3(0, 1.5, 0), k % 10 != 3));
  ASSERT_TRUE(h);
  EXPECT_NEAR(h->measured_m, 1.5, 1e-12);
  EXPECT_EQ(h->t_ns, head_at(0.5, Vec3::Zero()).t_ns);
}

TEST(StandingHeight, AnySampleRateWithoutAllocatingAndBadOptionsRefused) {
  // 1 kHz (above the detector's 250 Hz spacing): found at 0.5 s all the same, no allocation.
  StandingHeightDetector d;
  std::optional<StandingHeight> h;
  {
    test::AllocationCounter allocations;
    for (int k = 0; k <= 600 && !h; ++k) h = d.push(head_at(k / 1000.0, Vec3(0.001 * (k % 3), 1.7, 0)));
    EXPECT_EQ(allocations.count(), 0);
  }
  ASSERT_TRUE(h);
  EXPECT_NEAR(h->t_ns * 1e-9, 0.5, 0.0045);
  EXPECT_NEAR(h->measured_m, 1.7, 1e-12);
  StandingHeightOptions bad;
  bad.still_s = 0.0;
  EXPECT_NE(validate(bad).find("still_s"), std::string::npos);
  bad = {};
  bad.fallback_percentile = 120.0;
  EXPECT_NE(validate(bad).find("fallback_percentile"), std::string::npos);
}

// The detector's options come from code, never a user: a bad one is a bug (issue 45 item 5).
TEST(StandingHeightDeathTest, BadOptionsAreABug) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  StandingHeightOptions bad;
  bad.fallback_percentile = 120.0;
  EXPECT_DEATH(StandingHeightDetector{bad}, "bug: StandingHeightOptions: fallback_percentile");
}

TEST(StandingHeight, CalibrationAppliesPlausibleHeightsOnly) {
  const Motion walk = read_bvh(test::fixtures() / "walk_60.bvh");
  IkReconstructor ik(walk.skeleton);
  const double before = ik.head_height_m();
  std::string err = calibrate_from_head_height(ik, 0.3);
  EXPECT_NE(err.find("stand up straight"), std::string::npos) << err;
  EXPECT_FALSE(calibrate_from_head_height(ik, std::nan("")).empty());
  EXPECT_FALSE(calibrate_from_head_height(ik, 3.0).empty());
  EXPECT_DOUBLE_EQ(ik.head_height_m(), before);
  EXPECT_TRUE(calibrate_from_head_height(ik, 1.55).empty());
  EXPECT_NEAR(ik.head_height_m(), 1.55, 1e-12);
}

TEST(OneEuro, StillNoiseIsRemovedAndFastMotionFollowedClosely) {
  OneEuroOptions o;
  ASSERT_TRUE(validate(o).empty());
  OneEuroFilter still(o), ramp(o);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.002);
  double in_sq = 0.0, out_sq = 0.0;
  int n = 0;
  double lag = 0.0;
  for (int k = 0; k < 300; ++k) {
    const double t = k / 90.0;
    const Vec3 e(noise(rng), noise(rng), noise(rng));
    const TrackerSample s = still.filter(head_at(t, Vec3(0, 1.6, 0) + e));
    if (k >= 90) {  // after the first second
      in_sq += e.squaredNorm();
      out_sq += (s.position_m - Vec3(0, 1.6, 0)).squaredNorm();
      ++n;
    }
    // 1.5 m/s along x, no noise.
    const TrackerSample r = ramp.filter(head_at(t, Vec3(1.5 * t, 1.6, 0)));
    if (k >= 90) lag = std::max(lag, 1.5 * t - r.position_m.x());
  }
  EXPECT_LT(std::sqrt(out_sq / n), 0.5 * std::sqrt(in_sq / n));
  EXPECT_NEAR(still.position_noise_mm(), 2.0, 0.4);  // the noise gate measured it
  EXPECT_EQ(still.position_gain(), 1.0);
  // A clean tracker passes unchanged (the gate stays shut), so it has no lag at all.
  EXPECT_LT(ramp.position_noise_mm(), o.noise_gate_low_mm);
  EXPECT_LT(std::abs(lag), 1e-9);
}

TEST(OneEuro, NoiseGateTellsVigorousCleanMotionFromNoise) {
  // A clean 3 Hz wave of 20 cm sampled at 30 Hz (jerk 1,300 m/s^3) is not noise; the same wave
  // with 2 mm of noise is. The third differences alone could not tell them apart (docs/model.md).
  OneEuroOptions o;
  OneEuroFilter clean(o), noisy(o);
  std::mt19937_64 rng(9);
  std::normal_distribution<double> noise(0.0, 0.002);
  double worst_clean_step = 0.0;
  for (int k = 0; k < 150; ++k) {
    const double t = k / 30.0;
    const Vec3 p(0.2 * std::sin(2 * M_PI * 3 * t), 1.2, 0.0);
    const TrackerSample c = clean.filter(head_at(t, p));
    worst_clean_step = std::max(worst_clean_step, (c.position_m - p).norm());
    (void)noisy.filter(head_at(t, p + Vec3(noise(rng), noise(rng), noise(rng))));
  }
  EXPECT_LT(clean.position_noise_mm(), o.noise_gate_low_mm);
  EXPECT_EQ(worst_clean_step, 0.0);
  EXPECT_GT(noisy.position_noise_mm(), o.noise_gate_high_mm);  // 2 mm (plus a little of the wave)
  EXPECT_LT(noisy.position_noise_mm(), 3.0);
  EXPECT_EQ(noisy.position_gain(), 1.0);
  OneEuroOptions bad;
  bad.noise_gate_high_mm = bad.noise_gate_low_mm;
  EXPECT_NE(validate(bad).find("noise_gate"), std::string::npos);
  bad = {};
  bad.noise_window = 3;
  EXPECT_NE(validate(bad).find("noise_window"), std::string::npos);
}

TEST(OneEuro, RotationsAreSmoothedAndAGapStartsOver) {
  OneEuroFilter f;
  const Quat a = Quat::Identity();
  const Quat b(Eigen::AngleAxisd(0.02, Vec3::UnitY()));  // a 1.1 degree flicker
  TrackerSample s = f.filter(head_at(0.0, Vec3(0, 1.6, 0)));
  for (int k = 1; k < 40; ++k) {
    TrackerSample in = head_at(k / 90.0, Vec3(0, 1.6, 0));
    in.rotation = k % 2 ? b : a;
    s = f.filter(in);
  }
  // Near the middle of the flicker, not following it (0.01 rad from either end).
  const Quat mid(Eigen::AngleAxisd(0.01, Vec3::UnitY()));
  EXPECT_LT(geodesic_angle(s.rotation, mid), 0.004);
  // An invalid sample passes unchanged; the next valid one is not smoothed toward the old pose.
  const TrackerSample gap = f.filter(head_at(0.3, Vec3(9, 9, 9), false));
  EXPECT_FALSE(gap.valid);
  const TrackerSample back = f.filter(head_at(0.5, Vec3(1, 1.5, 0)));
  EXPECT_EQ(back.position_m, Vec3(1, 1.5, 0));
  OneEuroOptions bad;
  bad.min_cutoff_hz = 0.0;
  EXPECT_NE(validate(bad).find("min_cutoff_hz"), std::string::npos);
}
