// The output-side body filter (issue 18 item 4): PoseFilter (one_euro.h) on a synthetic jittery
// pose stream and on a constant one, and DiffusionReconstructor's body_filter option: on by
// default, no allocation in reconstruct(), reset() starts it over, and with it on the head and
// hands stay exactly on clean trackers while the untracked joints get smoother.
#include "bodyd/inference/diffusion.h"
#include "bodyd/inference/features.h"
#include "bodyd/inference/one_euro.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/rotation.h"
#include "bodyd/simulators/tracker_sim.h"

#include "bodyd/test/alloc_counter.h"
#include "../test_paths.h"
#include "default_model.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <vector>

using namespace bodyd;

namespace {

constexpr double kFps = 30.0;

std::int64_t frame_ns(size_t f) { return std::llround(static_cast<double>(f) * 1e9 / kFps); }

// Mean norm of the third difference x fps^3 of the positions of `joints` (all but joint 0 when
// empty) over the frames.
double jitter(const std::vector<GlobalPose>& poses, const std::vector<int>& joints = {}) {
  double sum = 0.0;
  int n = 0;
  for (size_t f = 3; f < poses.size(); ++f)
    for (size_t j = 1; j < poses[f].positions.size(); ++j) {
      if (!joints.empty() && std::find(joints.begin(), joints.end(), static_cast<int>(j)) == joints.end()) continue;
      sum += (poses[f].positions[j] - 3.0 * poses[f - 1].positions[j] + 3.0 * poses[f - 2].positions[j] -
              poses[f - 3].positions[j]).norm() * kFps * kFps * kFps;
      ++n;
    }
  return sum / n;
}

// The clip's poses with every joint's local rotation turned by noise of `deg` per axis and the
// Hips moved by `mm` per axis.
std::vector<Pose> jittery(const Motion& clip, double deg, double mm, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<Pose> out = clip.frames;
  for (Pose& p : out) {
    for (Quat& q : p.local_rotations) {
      const Vec3 v(normal(rng), normal(rng), normal(rng));
      q = (quat_from_axis_angle(v * (deg * M_PI / 180.0)) * q).normalized();
    }
    p.local_translations[features::kHips] += 1e-3 * mm * Vec3(normal(rng), normal(rng), normal(rng));
  }
  return out;
}

std::vector<GlobalPose> fk(const Skeleton& skeleton, const std::vector<Pose>& poses) {
  std::vector<GlobalPose> out;
  for (const Pose& p : poses) out.push_back(forward_kinematics(skeleton, p));
  return out;
}

BodyFilterOptions on(double cutoff_hz = 2.0) {
  BodyFilterOptions o;
  o.enabled = true;
  o.min_cutoff_hz = o.rot_min_cutoff_hz = cutoff_hz;
  return o;
}

std::shared_ptr<const inference::Model> tiny_model() {
  return inference::load_model(test::fixtures() / "tiny_model.safetensors");
}

std::vector<TrackerSample> trackers(const Motion& m) {
  SimOptions o;
  o.rate_hz = m.fps();  // at the frame times, so the newest sample is the truth
  o.seed = 3;
  return simulate_trackers(m, o);
}

// Pushes the samples up to each frame time, then reconstructs it.
std::vector<BodyPose> run(Reconstructor& r, const std::vector<TrackerSample>& samples, size_t frames) {
  std::vector<BodyPose> out;
  size_t next = 0;
  for (size_t f = 0; f < frames; ++f) {
    while (next < samples.size() && samples[next].t_ns <= frame_ns(f)) r.push(samples[next++]);
    BodyPose pose;
    EXPECT_TRUE(r.reconstruct(frame_ns(f), pose));
    out.push_back(pose);
  }
  return out;
}

std::vector<GlobalPose> globals(const std::vector<BodyPose>& poses) {
  std::vector<GlobalPose> out;
  for (const BodyPose& p : poses) out.push_back(p.global);
  return out;
}

bool identical(const std::vector<BodyPose>& a, const std::vector<BodyPose>& b) {
  if (a.size() != b.size()) return false;
  for (size_t f = 0; f < a.size(); ++f)
    for (size_t j = 0; j < a[f].global.positions.size(); ++j)
      if (a[f].global.positions[j] != b[f].global.positions[j] ||
          a[f].global.rotations[j].coeffs() != b[f].global.rotations[j].coeffs())
        return false;
  return true;
}

}  // namespace

TEST(OneEuro, PoseFilterSmoothsAJitteryPose) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  ASSERT_NEAR(clip.fps(), kFps, 1e-3);
  std::vector<Pose> poses = jittery(clip, 1.5, 5.0, 7);
  const double truth = jitter(fk(clip.skeleton, clip.frames));
  const double raw = jitter(fk(clip.skeleton, poses));
  PoseFilter filter(on(), clip.skeleton.size(), features::kHips);
  for (size_t f = 0; f < poses.size(); ++f) filter.filter(frame_ns(f), poses[f]);
  const double filtered = jitter(fk(clip.skeleton, poses));
  EXPECT_GT(raw, 3.0 * truth) << "the noise must dominate for the test to mean anything";
  EXPECT_LT(filtered, 0.4 * raw) << "truth " << truth << " raw " << raw << " filtered " << filtered;
}

TEST(OneEuro, PoseFilterPassesAConstantPoseAndDisabledChangesNothing) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const Pose still = clip.frames[10];
  PoseFilter filter(on(), clip.skeleton.size(), features::kHips);
  for (size_t f = 0; f < 60; ++f) {
    Pose p = still;
    filter.filter(frame_ns(f), p);
    for (size_t j = 0; j < p.local_rotations.size(); ++j) {
      EXPECT_LT((p.local_translations[j] - still.local_translations[j]).norm(), 1e-12) << "frame " << f << " joint " << j;
      EXPECT_LT(geodesic_angle(p.local_rotations[j], still.local_rotations[j]), 1e-9) << "frame " << f << " joint " << j;
    }
  }
  // Disabled: a no-op, bit for bit.
  std::vector<Pose> poses = jittery(clip, 1.5, 5.0, 8);
  const std::vector<Pose> before = poses;
  BodyFilterOptions disabled;
  disabled.enabled = false;
  PoseFilter off(disabled, clip.skeleton.size(), features::kHips);
  EXPECT_FALSE(off.enabled());
  for (size_t f = 0; f < poses.size(); ++f) {
    off.filter(frame_ns(f), poses[f]);
    for (size_t j = 0; j < poses[f].local_rotations.size(); ++j) {
      EXPECT_EQ(poses[f].local_rotations[j].coeffs(), before[f].local_rotations[j].coeffs());
      EXPECT_EQ(poses[f].local_translations[j], before[f].local_translations[j]);
    }
  }
}

TEST(OneEuro, BodyFilterOptionsAreValidated) {
  EXPECT_EQ(validate(BodyFilterOptions{}), "");
  EXPECT_TRUE(BodyFilterOptions{}.enabled);  // on: its defaults were chosen on held-out styles
  BodyFilterOptions o;
  o.min_cutoff_hz = 0.0;
  EXPECT_EQ(validate(o), "body_filter min_cutoff_hz must be > 0, not 0");
  o = {};
  o.rot_beta_per_rad_s = -1.0;
  EXPECT_EQ(validate(o), "body_filter rot_beta_per_rad_s must be >= 0, not -1");
  // The tracker filter's messages keep their name.
  OneEuroOptions t;
  t.min_cutoff_hz = 0.0;
  EXPECT_EQ(validate(t), "filter min_cutoff_hz must be > 0, not 0");
}

TEST(Diffusion, BodyFilterIsOnByDefaultAndRefusesBadOptions) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip);
  DiffusionOptions off;
  off.body_filter.enabled = false;
  DiffusionReconstructor a(tiny_model(), off);
  DiffusionOptions off_other = off;
  off_other.body_filter.min_cutoff_hz = 0.1;  // ignored while disabled
  DiffusionReconstructor b(tiny_model(), off_other);
  DiffusionReconstructor c(tiny_model());  // the defaults: on
  DiffusionOptions with;
  with.body_filter = on(BodyFilterOptions{}.min_cutoff_hz);
  DiffusionReconstructor d(tiny_model(), with);
  const auto ra = run(a, samples, 60), rb = run(b, samples, 60), rc = run(c, samples, 60),
             rd = run(d, samples, 60);
  EXPECT_TRUE(identical(ra, rb));
  EXPECT_FALSE(identical(ra, rc));  // on, it changes the poses
  EXPECT_TRUE(identical(rc, rd));   // the default is the filter on at its default cutoffs
  DiffusionOptions bad;
  bad.body_filter.rot_min_cutoff_hz = -1.0;
  EXPECT_THROW(DiffusionReconstructor(tiny_model(), bad), UserError);
  // The foot lock's options are checked too: a NaN or out-of-range value never reaches the state.
  EXPECT_EQ(validate_foot_lock(DiffusionOptions{}), "");
  DiffusionOptions lock = {};
  lock.foot_unlock_distance_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(validate_foot_lock(lock).find("foot_unlock_distance_m"), std::string::npos);
  EXPECT_THROW(DiffusionReconstructor(tiny_model(), lock), UserError);
  lock = {};
  lock.contact_on = 1.5f;
  EXPECT_NE(validate_foot_lock(lock).find("contact_on"), std::string::npos);
  lock = {};
  lock.foot_release_half_life_s = 0.0;
  EXPECT_NE(validate_foot_lock(lock).find("foot_release_half_life_s"), std::string::npos);
  // So is the arms' elbow pole bias.
  for (const double bias : {std::numeric_limits<double>::quiet_NaN(), -0.1, 11.0}) {
    DiffusionOptions arms;
    arms.elbow_pole_bias_m = bias;
    EXPECT_NE(validate_foot_lock(arms).find("elbow_pole_bias_m"), std::string::npos) << bias;
    EXPECT_THROW(DiffusionReconstructor(tiny_model(), arms), UserError) << bias;
  }
}

TEST(Diffusion, BodyFilterDoesNotAllocateAndResetStartsItOver) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip);
  DiffusionOptions with;
  with.body_filter = on();
  DiffusionReconstructor r(tiny_model(), with);
  BodyPose pose;
  size_t next = 0;
  std::int64_t allocations = 0;
  std::vector<BodyPose> first;
  for (size_t f = 0; f < 60; ++f) {
    while (next < samples.size() && samples[next].t_ns <= frame_ns(f)) r.push(samples[next++]);
    if (f < 2) {
      ASSERT_TRUE(r.reconstruct(frame_ns(f), pose));  // the first call may size `pose`
    } else {
      test::AllocationCounter counter;
      ASSERT_TRUE(r.reconstruct(frame_ns(f), pose));
      allocations += counter.count();
    }
    first.push_back(pose);
  }
  EXPECT_EQ(allocations, 0);
  // reset(): the filter's history goes with the rest, so the same stream gives the same poses.
  r.reset();
  EXPECT_TRUE(identical(first, run(r, samples, 60)));
}

class DefaultModelBodyFilter : public test::DefaultModelTest {};

// With the body filter on, the head and hands are still exactly on clean trackers (the filter
// acts before the tracked joints are fitted), and the untracked joints are smoother.
TEST_F(DefaultModelBodyFilter, HeadAndHandsExactlyOnCleanTrackersAndTheBodySmoother) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip);
  const auto frames = static_cast<size_t>(clip.frame_count());
  DiffusionOptions without, with;
  without.body_filter.enabled = false;
  with.body_filter = on(1.0);
  DiffusionReconstructor a(model_, without), b(model_, with);
  const auto off = run(a, samples, frames), filtered = run(b, samples, frames);
  double head_m = 0, head_deg = 0, hand_m = 0;
  for (size_t f = 0; f < frames; ++f) {
    const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
    const auto head = static_cast<size_t>(features::kHead);
    head_m = std::max(head_m, (filtered[f].global.positions[head] - truth.positions[head]).norm());
    head_deg = std::max(head_deg,
                        geodesic_angle(filtered[f].global.rotations[head], truth.rotations[head]) * 180 / M_PI);
    for (int j : {features::kHandL, features::kHandR})
      hand_m = std::max(hand_m, (filtered[f].global.positions[static_cast<size_t>(j)] -
                                 truth.positions[static_cast<size_t>(j)]).norm());
  }
  EXPECT_LT(head_m, 0.001);
  EXPECT_LT(head_deg, 0.5);
  EXPECT_LT(hand_m, 0.001);
  std::vector<int> untracked;
  for (int j = 1; j < clip.skeleton.size(); ++j)
    if (j != features::kHead && j != features::kHandL && j != features::kHandR) untracked.push_back(j);
  const double j_off = jitter(globals(off), untracked), j_on = jitter(globals(filtered), untracked);
  EXPECT_LT(j_on, j_off) << "off " << j_off << " on " << j_on;
}
