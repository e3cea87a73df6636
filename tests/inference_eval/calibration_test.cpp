// Height calibration from the head tracker (calibration.h) and the tracker filter (one_euro.h).
#include "bodyd/inference/calibration.h"
#include "bodyd/inference/ik.h"
#include "bodyd/inference/one_euro.h"

#include "bodyd/motion/bvh.h"

#include "../test_paths.h"

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

TEST(StandingHeight, ReportsTheMeanHeightOfTheFirstStillSecondOnce) {
  // 90 Hz: walking for 0.5 s, then standing at 1.60 m with +-5 mm sway for 2 s.
  StandingHeightDetector d;
  std::optional<double> found;
  double found_at_s = -1.0, sum = 0.0;
  int n = 0, reports = 0;
  for (int k = 0; k < 225; ++k) {
    const double t = k / 90.0;
    Vec3 p = t < 0.5 ? Vec3(0.8 * t, 1.45, 0.0) : Vec3(0.4, 1.60 + 0.005 * std::sin(7.0 * t), 0.0);
    if (t >= 0.5 && !found) {
      sum += p.y();
      ++n;
    }
    if (const auto h = d.push(head_at(t, p))) {
      ++reports;
      found = h;
      found_at_s = t;
    }
    // Other roles and invalid samples are ignored.
    TrackerSample hand = head_at(t, Vec3(5, 0, 0));
    hand.role = Role::LeftHand;
    EXPECT_FALSE(d.push(hand));
  }
  ASSERT_TRUE(found);
  EXPECT_EQ(reports, 1);
  // The still stretch starts at the first standing sample (t = 0.5 s, 15 cm above the last step).
  EXPECT_NEAR(found_at_s, 1.5, 1e-9);
  EXPECT_NEAR(*found, sum / n, 1e-12);
  EXPECT_TRUE(d.done());
  d.reset();
  EXPECT_FALSE(d.done());
  EXPECT_FALSE(d.height_m());
}

TEST(StandingHeight, SittingOrNeverStillGivesUpWithoutAHeight) {
  StandingHeightOptions o;
  o.search_s = 3.0;
  StandingHeightDetector sitting(o), moving(o);
  for (int k = 0; k < 450; ++k) {
    const double t = k / 90.0;
    EXPECT_FALSE(sitting.push(head_at(t, Vec3(0, 0.85, 0))));  // still, but below min_height_m
    EXPECT_FALSE(moving.push(head_at(t, Vec3(std::sin(3.0 * t), 1.6, 0))));
  }
  EXPECT_TRUE(sitting.done());
  EXPECT_TRUE(moving.done());
  EXPECT_FALSE(sitting.height_m());
  // A gap (invalid samples) neither starts nor ends a stretch.
  StandingHeightDetector gap;
  std::optional<double> h;
  for (int k = 0; k <= 90 && !h; ++k) h = gap.push(head_at(k / 90.0, Vec3(0, 1.5, 0), k % 10 != 3));
  ASSERT_TRUE(h);
  EXPECT_NEAR(*h, 1.5, 1e-12);
}

TEST(StandingHeight, CalibrationAppliesPlausibleHeightsOnly) {
  const Motion walk = read_bvh(test::fixtures() / "walk_60.bvh");
  IkReconstructor ik(walk.skeleton);
  const double before = ik.user_height();
  std::string err = calibrate_from_head_height(ik, 0.3);
  EXPECT_NE(err.find("stand up straight"), std::string::npos) << err;
  EXPECT_FALSE(calibrate_from_head_height(ik, std::nan("")).empty());
  EXPECT_FALSE(calibrate_from_head_height(ik, 3.0).empty());
  EXPECT_DOUBLE_EQ(ik.user_height(), before);
  EXPECT_TRUE(calibrate_from_head_height(ik, 1.55).empty());
  EXPECT_NEAR(ik.user_height(), 1.55, 1e-12);
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
  // Lag at speed tends to 1 / (2 pi beta) m (8 mm for beta 20) and stays below it.
  EXPECT_GT(lag, 0.0);
  EXPECT_LT(lag, 1.0 / (2.0 * M_PI * o.beta_per_m_s));
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
