#include "bodyd/inference/tracker_history.h"

#include "bodyd/test/alloc_counter.h"
#include "bodyd/test/tracker_sample.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using namespace bodyd;

namespace {

constexpr std::int64_t kMs = 1'000'000;

using test::tracker_sample;

Quat yaw_deg(double deg) { return quat_from_yaw(deg * M_PI / 180.0); }

}  // namespace

TEST(TrackerHistory, InterpolatesBetweenSamplesWhenNowAllowsIt) {
  TrackerHistory h;
  ASSERT_TRUE(h.push(tracker_sample(Role::LeftHand, 100 * kMs, true, Vec3(0, 1, 0), yaw_deg(0))));
  ASSERT_TRUE(h.push(tracker_sample(Role::LeftHand, 200 * kMs, true, Vec3(1, 1, -2), yaw_deg(90))));
  TrackerSample out;
  // A quarter of the way from the first to the second sample; both are <= now.
  ASSERT_TRUE(h.query(Role::LeftHand, 125 * kMs, 200 * kMs, out));
  EXPECT_EQ(out.t_ns, 125 * kMs);
  EXPECT_EQ(out.role, Role::LeftHand);
  EXPECT_NEAR((out.position_m - Vec3(0.25, 1, -0.5)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(geodesic_angle(out.rotation, yaw_deg(22.5)), 0.0, 1e-9);
}

TEST(TrackerHistory, DefaultQueryIsCausalAndHoldsTheNewestEarlierSample) {
  TrackerHistory h;
  ASSERT_TRUE(h.push(tracker_sample(Role::Head, 100 * kMs, true, Vec3(0, 1, 0))));
  ASSERT_TRUE(h.push(tracker_sample(Role::Head, 200 * kMs, true, Vec3(1, 1, 0))));
  TrackerSample out;
  // The sample at 200 ms is already pushed but later than 150 ms: it must not be used.
  ASSERT_TRUE(h.query(Role::Head, 150 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(0, 1, 0));
  // now < t is treated as now = t.
  ASSERT_TRUE(h.query(Role::Head, 150 * kMs, 120 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(0, 1, 0));
  // Exactly at a sample: that sample.
  ASSERT_TRUE(h.query(Role::Head, 200 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(1, 1, 0));
  // Before the first sample: nothing.
  EXPECT_FALSE(h.query(Role::Head, 99 * kMs, 300 * kMs, out));
  EXPECT_FALSE(out.valid);
  // Another role has nothing.
  EXPECT_FALSE(h.query(Role::RightHand, 200 * kMs, out));
}

TEST(TrackerHistory, HeldSampleExpiresAfterTheTimeout) {
  TrackerHistoryOptions o;
  o.timeout_ns = 250 * kMs;
  TrackerHistory h(o);
  ASSERT_TRUE(h.push(tracker_sample(Role::Head, 1000 * kMs, true, Vec3(0, 1.5, 0))));
  TrackerSample out;
  EXPECT_TRUE(h.query(Role::Head, 1250 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(0, 1.5, 0));
  EXPECT_FALSE(h.query(Role::Head, 1251 * kMs, out));
  // Two valid samples further apart than the timeout are not interpolated: the nearer decides.
  ASSERT_TRUE(h.push(tracker_sample(Role::Head, 2000 * kMs, true, Vec3(0, 1.0, 0))));
  EXPECT_TRUE(h.query(Role::Head, 1100 * kMs, 2000 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(0, 1.5, 0));
  EXPECT_FALSE(h.query(Role::Head, 1500 * kMs, 2000 * kMs, out));  // 500 ms from both
  EXPECT_TRUE(h.query(Role::Head, 1900 * kMs, 2000 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(0, 1.0, 0));
}

TEST(TrackerHistory, InvalidSamplesMakeTheirNeighbourhoodInvalid) {
  TrackerHistory h;
  ASSERT_TRUE(h.push(tracker_sample(Role::RightHand, 0, true, Vec3(1, 0, 0))));
  ASSERT_TRUE(h.push(tracker_sample(Role::RightHand, 100 * kMs, false)));
  ASSERT_TRUE(h.push(tracker_sample(Role::RightHand, 200 * kMs, true, Vec3(3, 0, 0))));
  TrackerSample out;
  // Holding an invalid sample: invalid, although an older valid one is within the timeout.
  EXPECT_FALSE(h.query(Role::RightHand, 150 * kMs, out));
  EXPECT_FALSE(h.query(Role::RightHand, 100 * kMs, out));
  // Between a valid and an invalid sample: the nearer one decides.
  EXPECT_TRUE(h.query(Role::RightHand, 40 * kMs, 200 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(1, 0, 0));
  EXPECT_FALSE(h.query(Role::RightHand, 60 * kMs, 200 * kMs, out));
  EXPECT_TRUE(h.query(Role::RightHand, 160 * kMs, 200 * kMs, out));
  EXPECT_EQ(out.position_m, Vec3(3, 0, 0));
  ASSERT_NE(h.newest_valid_at_or_before(Role::RightHand, 150 * kMs), nullptr);
  EXPECT_EQ(h.newest_valid_at_or_before(Role::RightHand, 150 * kMs)->t_ns, 0);
  EXPECT_EQ(h.newest_valid_at_or_before(Role::RightHand, -1), nullptr);
}

TEST(TrackerHistory, IgnoresAndCountsOlderSamplesPerRole) {
  TrackerHistory h;
  EXPECT_TRUE(h.push(tracker_sample(Role::Head, 100, true)));
  EXPECT_TRUE(h.push(tracker_sample(Role::LeftHand, 50, true)));  // roles are independent
  EXPECT_FALSE(h.push(tracker_sample(Role::Head, 99, true, Vec3(9, 9, 9))));
  EXPECT_EQ(h.ignored_count(), 1);
  EXPECT_EQ(h.size(Role::Head), 1);
  // Equal time is kept; the later arrival wins.
  EXPECT_TRUE(h.push(tracker_sample(Role::Head, 100, true, Vec3(2, 0, 0))));
  TrackerSample out;
  ASSERT_TRUE(h.query(Role::Head, 100, out));
  EXPECT_EQ(out.position_m, Vec3(2, 0, 0));
  ASSERT_NE(h.newest(Role::Head), nullptr);
  EXPECT_EQ(h.newest(Role::Head)->position_m, Vec3(2, 0, 0));
  h.clear();
  EXPECT_EQ(h.size(Role::Head), 0);
  EXPECT_EQ(h.ignored_count(), 0);
  EXPECT_EQ(h.newest(Role::Head), nullptr);
  EXPECT_EQ(h.first_valid(Role::Head), nullptr);
}

TEST(TrackerHistory, RingKeepsTheNewestAndFirstValidSurvives) {
  TrackerHistoryOptions o;
  o.capacity = 4;
  TrackerHistory h(o);
  EXPECT_TRUE(h.push(tracker_sample(Role::Head, 0, false)));
  for (int i = 1; i <= 10; ++i) EXPECT_TRUE(h.push(tracker_sample(Role::Head, i * 10 * kMs, true, Vec3(i, 0, 0))));
  EXPECT_EQ(h.size(Role::Head), 4);
  TrackerSample out;
  // Samples 7..10 (70..100 ms) remain: 65 ms has nothing at or before it any more.
  EXPECT_FALSE(h.query(Role::Head, 65 * kMs, 100 * kMs, out));
  ASSERT_TRUE(h.query(Role::Head, 75 * kMs, 100 * kMs, out));
  EXPECT_NEAR(out.position_m.x(), 7.5, 1e-12);
  ASSERT_TRUE(h.query(Role::Head, 100 * kMs, out));
  EXPECT_EQ(out.position_m.x(), 10.0);
  // The first valid sample (not the invalid one at 0) is kept for padding.
  ASSERT_NE(h.first_valid(Role::Head), nullptr);
  EXPECT_EQ(h.first_valid(Role::Head)->t_ns, 10 * kMs);
  EXPECT_EQ(h.first_valid(Role::Head)->position_m.x(), 1.0);
}

TEST(TrackerHistoryDeathTest, BadOptionsAreABug) {
  // No user option reaches them: the reconstructors pass their own.
  TrackerHistoryOptions o;
  o.capacity = 1;
  EXPECT_DEATH(TrackerHistory{o}, "bug: TrackerHistory: capacity must be at least 2 samples, got 1");
  o.capacity = 8;
  o.timeout_ns = -1;
  EXPECT_DEATH(TrackerHistory{o}, "bug: TrackerHistory: timeout_ns must not be negative");
}

TEST(TrackerHistory, PushAndQueryDoNotAllocate) {
  TrackerHistoryOptions o;
  o.capacity = 16;
  TrackerHistory h(o);
  TrackerSample out;
  std::int64_t allocations = 0;
  {
    test::AllocationCounter counter;
    for (int i = 0; i < 100; ++i) {
      (void)h.push(tracker_sample(Role::LeftHand, i * 11 * kMs, i % 7 != 0, Vec3(i, 0, 0), yaw_deg(i)));
      (void)h.query(Role::LeftHand, i * 11 * kMs - 5 * kMs, i * 11 * kMs, out);
      (void)h.first_valid(Role::LeftHand);
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
}

// Issue 11, second wall: a sample with non-finite or absurd values is refused and counted, and
// queries see only the good samples around it.
TEST(TrackerHistory, RefusesNonFiniteAndAbsurdSamplesAndCountsThem) {
  TrackerHistory h;
  ASSERT_TRUE(h.push(tracker_sample(Role::Head, 100 * kMs, true, Vec3(0, 1.6, 0))));
  const double nan = std::nan("");
  EXPECT_FALSE(h.push(tracker_sample(Role::Head, 110 * kMs, true, Vec3(1e300, 1.6, 0))));
  EXPECT_FALSE(h.push(tracker_sample(Role::Head, 120 * kMs, true, Vec3(0, nan, 0))));
  EXPECT_FALSE(h.push(tracker_sample(Role::Head, 130 * kMs, true, Vec3(0, 0, -101.0))));
  EXPECT_FALSE(h.push(tracker_sample(Role::Head, 140 * kMs, true, Vec3(0, 1.6, 0), Quat(5, 0, 0, 0))));
  EXPECT_FALSE(h.push(tracker_sample(Role::Head, 150 * kMs, true, Vec3(0, 1.6, 0), Quat(nan, 0, 0, 1))));
  EXPECT_FALSE(h.push(tracker_sample(Role::Head, std::numeric_limits<std::int64_t>::max(), false)));
  EXPECT_EQ(h.refused_count(), 6);
  EXPECT_EQ(h.ignored_count(), 0);
  EXPECT_EQ(h.size(Role::Head), 1);
  // At the limit is still accepted; an invalid sample's (unused) pose is not checked.
  EXPECT_TRUE(h.push(tracker_sample(Role::Head, 200 * kMs, true, Vec3(100.0, 1.6, -100.0))));
  EXPECT_TRUE(h.push(tracker_sample(Role::LeftHand, 200 * kMs, false, Vec3(nan, nan, nan))));
  TrackerSample out;
  ASSERT_TRUE(h.query(Role::Head, 150 * kMs, 200 * kMs, out));
  EXPECT_TRUE(out.position_m.allFinite());
  EXPECT_NEAR(out.position_m.x(), 50.0, 1e-9);
  // clear() keeps the running count.
  h.clear();
  EXPECT_EQ(h.refused_count(), 6);
}
