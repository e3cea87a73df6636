// The online diffusion reconstructor: determinism, causality, no per-frame allocation, hands on
// the trackers, a lost hand coming back smoothly, calibration. Uses the tiny parity model
// (tests/data) for the properties that do not depend on a trained model, and the shipped default
// model (models/) for the ones that do.
#include "bodyd/inference/diffusion.h"
#include "bodyd/inference/evaluation.h"
#include "bodyd/inference/factory.h"
#include "bodyd/inference/features.h"
#include "bodyd/simulators/tracker_sim.h"

#include "bodyd/test/alloc_counter.h"
#include "../test_paths.h"
#include "default_model.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <optional>

using namespace bodyd;

namespace {

std::shared_ptr<const inference::Model> tiny_model() {
  return inference::load_model(test::fixtures() / "tiny_model.safetensors");
}

struct Outputs {
  std::vector<BodyPose> poses;
};

// Feeds the clip's trackers (30 Hz at the frame times unless `options` says otherwise) and
// reconstructs at every frame time, pushing only samples up to that time.
Outputs feed_and_reconstruct(Reconstructor& r, const std::vector<TrackerSample>& samples, const std::vector<std::int64_t>& times) {
  Outputs run;
  size_t next = 0;
  for (std::int64_t t : times) {
    while (next < samples.size() && samples[next].t_ns <= t) r.push(samples[next++]);
    BodyPose pose;
    EXPECT_TRUE(r.reconstruct(t, pose));
    run.poses.push_back(pose);
  }
  return run;
}

std::vector<std::int64_t> frame_times(const Motion& m) {
  std::vector<std::int64_t> t;
  for (int f = 0; f < m.frame_count(); ++f) t.push_back(static_cast<std::int64_t>(std::llround(f * m.frame_time_s * 1e9)));
  return t;
}

std::vector<TrackerSample> trackers(const Motion& m, double rate_hz = 0, double dropout_rate_hz = 0) {
  SimOptions o;
  o.rate_hz = rate_hz > 0 ? rate_hz : m.fps();
  o.dropout_rate_hz = dropout_rate_hz;
  o.seed = 3;
  return simulate_trackers(m, o);
}

}  // namespace

TEST(Diffusion, DeterministicForASeed) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip);
  const auto times = frame_times(clip);
  DiffusionReconstructor a(tiny_model()), b(tiny_model());
  const Outputs ra = feed_and_reconstruct(a, samples, times), rb = feed_and_reconstruct(b, samples, times);
  ASSERT_EQ(ra.poses.size(), rb.poses.size());
  for (size_t f = 0; f < ra.poses.size(); ++f)
    for (size_t j = 0; j < ra.poses[f].global.positions.size(); ++j)
      ASSERT_EQ(ra.poses[f].global.positions[j], rb.poses[f].global.positions[j]) << "frame " << f;
  // reset() starts over: the same run again gives the same poses.
  a.reset();
  const Outputs rc = feed_and_reconstruct(a, samples, times);
  for (size_t f = 0; f < ra.poses.size(); ++f)
    EXPECT_EQ(ra.poses[f].global.positions[5], rc.poses[f].global.positions[5]) << "frame " << f;
  // A different seed gives a different reconstruction.
  DiffusionOptions other;
  other.seed = 99;
  DiffusionReconstructor d(tiny_model(), other);
  const Outputs rd = feed_and_reconstruct(d, samples, times);
  double diff = 0;
  for (size_t f = 0; f < ra.poses.size(); ++f)
    diff += (ra.poses[f].global.positions[1] - rd.poses[f].global.positions[1]).norm();
  EXPECT_GT(diff, 0.0);
}

// bodyd-eval loads the model file once and makes every clip's reconstructor from it: two
// reconstructors sharing one loaded model, run frame by frame in turn, give what a reconstructor
// that loaded the file itself gives (no state lives in the shared model).
TEST(Factory, ReconstructorsSharingOneLoadedModelMatchOneThatLoadsTheFile) {
  const std::filesystem::path path = test::fixtures() / "tiny_model.safetensors";
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip);
  const auto times = frame_times(clip);
  const auto own = make_reconstructor("diffusion", path, nullptr);
  const Outputs reference = feed_and_reconstruct(*own, samples, times);

  const std::shared_ptr<const inference::Model> model = load_reconstructor_model(path);
  std::array<std::unique_ptr<Reconstructor>, 2> shared = {make_reconstructor_of("diffusion", model, nullptr),
                                                           make_reconstructor_of("diffusion", model, nullptr)};
  size_t next = 0;
  for (size_t f = 0; f < times.size(); ++f) {
    for (; next < samples.size() && samples[next].t_ns <= times[f]; ++next)
      for (auto& r : shared) r->push(samples[next]);
    for (auto& r : shared) {
      BodyPose pose;
      ASSERT_TRUE(r->reconstruct(times[f], pose));
      for (size_t j = 0; j < pose.global.positions.size(); ++j)
        ASSERT_EQ(pose.global.positions[j], reference.poses[f].global.positions[j]) << "frame " << f << " joint " << j;
    }
  }
}

TEST(Factory, ADiffusionReconstructorWithoutAModelSaysWhatToPass) {
  for (const auto& make : std::vector<std::function<std::unique_ptr<Reconstructor>()>>{
           [] { return make_reconstructor("diffusion", std::filesystem::path{}, nullptr); },
           [] { return make_reconstructor_of("diffusion", nullptr, nullptr); }}) {
    try {
      (void)make();
      FAIL() << "no error";
    } catch (const ReconstructorError& e) {
      EXPECT_NE(std::string(e.what()).find("needs a model file (--model"), std::string::npos) << e.what();
    }
  }
  try {
    (void)load_reconstructor_model(test::fixtures() / "no_such_model.safetensors");
    FAIL() << "no error";
  } catch (const ReconstructorError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot load the model"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no_such_model.safetensors"), std::string::npos) << e.what();
  }
}

TEST(Diffusion, CausalChangingFutureSamplesNeverChangesPastOutputs) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip, 90.0);
  const auto times = frame_times(clip);
  const auto model = tiny_model();
  const CausalityReport report = check_causality([&] { return std::make_unique<DiffusionReconstructor>(model); },
                                                 samples, times, times[30]);
  EXPECT_TRUE(report.causal) << report.message;
  EXPECT_GT(report.frames_checked, 25);
  EXPECT_TRUE(report.future_changed);  // the check could have failed
}

TEST(Diffusion, ReconstructDoesNotAllocateOnceWarm) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip, 90.0);
  const auto times = frame_times(clip);
  DiffusionReconstructor r(tiny_model());
  BodyPose pose;
  size_t next = 0;
  std::int64_t allocations = 0;
  for (size_t f = 0; f < times.size(); ++f) {
    while (next < samples.size() && samples[next].t_ns <= times[f]) r.push(samples[next++]);
    if (f < 2) {
      ASSERT_TRUE(r.reconstruct(times[f], pose));  // the first call may size `pose`
      continue;
    }
    test::AllocationCounter counter;
    ASSERT_TRUE(r.reconstruct(times[f], pose));
    allocations += counter.count();
  }
  EXPECT_EQ(allocations, 0);
}

// tcn-v1 (W = 10) through the same reconstructor: once the window is full of emitted frames the
// sampler takes its newest-frame pass (Denoiser::forward_newest); it stays causal, finite and
// allocation-free, and keeps the head on its tracker.
TEST(Diffusion, ATemporalNetworkRunsOnlineCausallyWithoutAllocating) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip, 90.0);
  const auto times = frame_times(clip);
  const auto model = inference::load_model(test::fixtures() / "tiny_tcn.safetensors");
  ASSERT_EQ(model->metadata.at("architecture"), "tcn-v1");
  const CausalityReport report = check_causality([&] { return std::make_unique<DiffusionReconstructor>(model); },
                                                 samples, times, times[30]);
  EXPECT_TRUE(report.causal) << report.message;
  EXPECT_TRUE(report.future_changed);

  // Samples at the clip's 30 Hz, so the head tracker is the Head joint (HeadAndHandsExactlyOnCleanTrackers).
  const auto at_30_hz = trackers(clip);
  DiffusionReconstructor r(model);
  BodyPose pose;
  size_t next = 0;
  std::int64_t allocations = 0;
  const auto head = static_cast<size_t>(features::kHead);
  for (size_t f = 0; f < times.size(); ++f) {
    while (next < at_30_hz.size() && at_30_hz[next].t_ns <= times[f]) r.push(at_30_hz[next++]);
    test::AllocationCounter counter;
    ASSERT_TRUE(r.reconstruct(times[f], pose));
    if (f >= 2) allocations += counter.count();  // the first calls may size `pose`
    for (const Vec3& p : pose.global.positions) ASSERT_TRUE(p.allFinite()) << "frame " << f;
    const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
    EXPECT_LT((pose.global.positions[head] - truth.positions[head]).norm(), 1e-3) << "frame " << f;
  }
  EXPECT_EQ(allocations, 0);
}

TEST(Diffusion, NoPoseBeforeTheFirstHeadSampleAndTimesMustIncrease) {
  DiffusionReconstructor r(tiny_model());
  BodyPose pose;
  EXPECT_FALSE(r.reconstruct(1000, pose));
  TrackerSample s;
  s.role = Role::Head;
  s.valid = true;
  s.t_ns = 0;
  s.position_m = Vec3(0, 1.5, 0);
  r.push(s);
  EXPECT_TRUE(r.reconstruct(1000, pose));
  EXPECT_FALSE(r.reconstruct(1000, pose));  // not increasing
  EXPECT_TRUE(r.reconstruct(2000, pose));
}

// Issue 20 item 9: a calibration (the daemon's auto calibration, bodyd-ctl calibrate) changes the
// skeleton between two samples. The first pose after it must still say the hands are tracked
// when their trackers were reporting just before (the head's sample came first, the hands'
// next ones had not arrived), and lost when they were lost.
TEST(Diffusion, TrackingFlagsSurviveACalibration) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  auto samples = trackers(clip, 90.0);
  for (const bool right_hand_lost : {false, true}) {
    SCOPED_TRACE(right_hand_lost ? "right hand lost" : "both hands tracked");
    DiffusionReconstructor r(tiny_model());
    // Every sample up to 1 s, then the head's next one only.
    std::int64_t last_t = 0;
    size_t next = 0;
    for (; next < samples.size() && samples[next].t_ns <= 1'000'000'000; ++next) {
      TrackerSample s = samples[next];
      if (right_hand_lost && s.role == Role::RightHand && s.t_ns > 500'000'000) s.valid = false;
      r.push(s);
      last_t = s.t_ns;
    }
    BodyPose before;
    ASSERT_TRUE(r.reconstruct(last_t, before));
    EXPECT_TRUE(before.tracker_valid[1]);
    EXPECT_EQ(before.tracker_valid[2], !right_hand_lost);
    r.set_head_height_m(r.model_height() * 1.1);
    while (next < samples.size() && samples[next].role != Role::Head) ++next;
    ASSERT_LT(next, samples.size());
    const std::int64_t t = samples[next].t_ns;
    ASSERT_GT(t, last_t);
    r.push(samples[next]);
    BodyPose after;
    ASSERT_TRUE(r.reconstruct(t, after));
    EXPECT_TRUE(after.tracker_valid[0]);
    EXPECT_TRUE(after.tracker_valid[1]) << "the left hand was tracked " << (t - last_t) / 1000 << " us earlier";
    EXPECT_EQ(after.tracker_valid[2], !right_hand_lost);
    // The kept samples are in the new scale: the hand is where the tracker was (user units).
    const TrackerSample* left = nullptr;
    for (size_t i = next; i-- > 0;)
      if (samples[i].role == Role::LeftHand) {
        left = &samples[i];
        break;
      }
    ASSERT_NE(left, nullptr);
    EXPECT_LT((after.global.positions[static_cast<size_t>(features::kHandL)] - left->position_m).norm(), 0.05);
  }
}

TEST(Diffusion, RejectsAModelOnAnotherSkeleton) {
  auto model = std::make_shared<inference::Model>(*tiny_model());
  model->skeleton.names[5] = "Kopf";
  EXPECT_THROW(DiffusionReconstructor r(model), UserError);
}

class DefaultModel : public test::DefaultModelTest {};

TEST_F(DefaultModel, HandsOnTheTrackersAndABelievableBody) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip);  // at the frame times, so the newest sample is the truth
  const auto times = frame_times(clip);
  DiffusionReconstructor r(model_);
  const Outputs run = feed_and_reconstruct(r, samples, times);
  double hand_err = 0, body_err = 0;
  int n = 0;
  for (size_t f = 0; f < times.size(); ++f) {
    const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
    for (int j : {features::kHandL, features::kHandR})
      hand_err += (run.poses[f].global.positions[static_cast<size_t>(j)] - truth.positions[static_cast<size_t>(j)]).norm();
    for (int j = 1; j < 22; ++j)
      body_err += (run.poses[f].global.positions[static_cast<size_t>(j)] - truth.positions[static_cast<size_t>(j)]).norm();
    n++;
  }
  EXPECT_LT(hand_err / (2 * n), 0.005);  // hands within 5 mm on average (IK onto the trackers)
  EXPECT_LT(body_err / (21 * n), 0.10);  // a walking body, not noise: mean joint error under 10 cm
}

TEST_F(DefaultModel, ALostHandComesBackSmoothly) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  auto samples = trackers(clip, 90.0);
  const auto times = frame_times(clip);
  // The left hand is lost from 0.6 s to 1.2 s.
  for (TrackerSample& s : samples)
    if (s.role == Role::LeftHand && s.t_ns >= 600'000'000 && s.t_ns < 1'200'000'000) s.valid = false;
  DiffusionReconstructor r(model_);
  const Outputs run = feed_and_reconstruct(r, samples, times);
  double max_step = 0, max_truth_step = 0;
  for (size_t f = 1; f < times.size(); ++f) {
    const auto j = static_cast<size_t>(features::kHandL);
    max_step = std::max(max_step, (run.poses[f].global.positions[j] - run.poses[f - 1].global.positions[j]).norm());
    const GlobalPose a = forward_kinematics(clip.skeleton, clip.frames[f - 1]);
    const GlobalPose b = forward_kinematics(clip.skeleton, clip.frames[f]);
    max_truth_step = std::max(max_truth_step, (b.positions[j] - a.positions[j]).norm());
    if (times[f] >= 600'000'000 && times[f] < 1'200'000'000) {
      EXPECT_FALSE(run.poses[f].tracker_valid[1]);
    }
  }
  // No pop: the hand never moves much more per frame than the real hand does.
  EXPECT_LT(max_step, max_truth_step + 0.05);
  // And it is back on the tracker by the end.
  const GlobalPose last = forward_kinematics(clip.skeleton, clip.frames.back());
  EXPECT_LT((run.poses.back().global.positions[features::kHandL] - last.positions[features::kHandL]).norm(), 0.01);
}

// A headset tracked by rotation only for 1.5 s mid-walk (issue 42: SteamVR's TrackingResult_
// Fallback_RotationOnly, which the bridge turns into lost head samples): the body follows the
// hands instead of standing where the head was last seen while the user walks on. Target: the
// waist's error inside the window at most twice its error outside.
TEST_F(DefaultModel, ALostHeadFollowsTheHandsWhileTheUserWalks) {
  if (!test::have_bandai()) GTEST_SKIP() << "no " << test::bandai();
  const Motion clip = read_bvh(test::bandai() / "dataset-2" / "dataset-2_walk_normal_002.bvh");
  auto samples = trackers(clip, 90.0);
  const auto times = frame_times(clip);
  constexpr std::int64_t kFrom = 4'000'000'000, kTo = 5'500'000'000;
  for (TrackerSample& s : samples)
    if (s.role == Role::Head && s.t_ns >= kFrom && s.t_ns < kTo) s.valid = false;
  DiffusionReconstructor r(model_);
  const Outputs run = feed_and_reconstruct(r, samples, times);
  const auto hips = static_cast<size_t>(features::kHips);
  double in = 0, out = 0, walked = 0;
  int n_in = 0, n_out = 0;
  Vec3 start = Vec3::Zero();
  for (size_t f = 0; f < times.size(); ++f) {
    if (times[f] < 2'500'000'000) continue;  // the reconstruction's history fills first
    const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
    const double e = (run.poses[f].global.positions[hips] - truth.positions[hips]).norm();
    if (times[f] >= kFrom && times[f] < kTo) {
      if (n_in == 0) start = truth.positions[hips];
      walked = (truth.positions[hips] - start).norm();
      in += e, ++n_in;
    } else {
      out += e, ++n_out;
    }
  }
  ASSERT_GT(n_in, 30);
  ASSERT_GT(walked, 1.0) << "the clip should walk through the window";
  std::cout << "waist error: " << 100 * out / n_out << " cm outside the window, " << 100 * in / n_in
            << " cm inside (the hips walked " << walked << " m in it)\n";
  EXPECT_LE(in / n_in, 2.0 * out / n_out);
}

// Body trackers (issue 44): the model observes their joints' entries. With hips and feet tracked
// the lower body is nearer the truth; rotation-only trackers (IMU) never make it worse (their
// missing positions must not overwrite the emitted past's: a bug once made hips:rot 2.1x worse).
TEST_F(DefaultModel, BodyTrackersAreUsedAndRotationOnlyOnesDoNoHarm) {
  if (!test::have_bandai()) GTEST_SKIP() << "no " << test::bandai();
  const Motion clip = read_bvh(test::bandai() / "dataset-2" / "dataset-2_walk_normal_002.bvh");
  const auto times = frame_times(clip);
  const auto error_cm = [&](const char* set_text) {
    std::string e;
    const std::optional<TrackerSet> set = parse_tracker_set(set_text, e);
    EXPECT_TRUE(set) << e;
    SimOptions o;
    o.rate_hz = clip.fps();
    o.roles = set->roles;
    o.rotation_only = set->rotation_only;
    DiffusionReconstructor r(model_);
    const Outputs run = feed_and_reconstruct(r, simulate_trackers(clip, o), times);
    double all = 0, lower = 0;
    int n = 0;
    for (size_t f = 60; f < times.size(); ++f, ++n) {
      const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
      for (size_t j = 1; j < 22; ++j) {
        const double d = (run.poses[f].global.positions[j] - truth.positions[j]).norm();
        all += d;
        if (j >= 14) lower += d;  // UpperLeg_L .. Toes_R
      }
    }
    return std::pair{100 * all / (21.0 * n), 100 * lower / (8.0 * n)};
  };
  const auto [base_all, base_lower] = error_cm("head,hands");
  const auto [hf_all, hf_lower] = error_cm("head,hands,hips,feet");
  const auto [rot_all, rot_lower] = error_cm("head,hands,hips:rot,feet:rot");
  std::cout << "mean joint / leg error, cm: head,hands " << base_all << " / " << base_lower << "; +hips,feet " << hf_all
            << " / " << hf_lower << "; +hips:rot,feet:rot " << rot_all << " / " << rot_lower << "\n";
  EXPECT_LT(hf_lower, 0.8 * base_lower);
  EXPECT_LE(rot_all, 1.05 * base_all);
}

// Issue 44 item 6: a tracked role is not replaced by a guess. A tracked hips and tracked feet sit
// on their trackers (the body and the legs reach them), tracked knees and elbows bend the legs
// and arms their way, and a foot tracked by rotation only turns toward the tracker's rotation. Trackers at 90 Hz (the
// clip's 30 fps frame times fall just before every third sample, so each frame is measured
// against its tracker's newest sample).
TEST_F(DefaultModel, TrackedHipsAndFeetSitOnTheirTrackersKneesAndElbowsBendTheLimbs) {
  if (!test::have_bandai()) GTEST_SKIP() << "no " << test::bandai();
  const Motion clip = read_bvh(test::bandai() / "dataset-2" / "dataset-2_walk_normal_002.bvh");
  const auto times = frame_times(clip);
  constexpr std::array<Role, 3> kPlaced{Role::Hips, Role::LeftFoot, Role::RightFoot};
  struct Errors {
    double off_tracker_max_cm = 0;     // hips and feet from their trackers' newest samples
    double foot_deg = 0, knee_cm = 0, elbow_cm = 0;  // from the truth, means over both sides
  };
  const auto run_set = [&](const char* set_text) {
    std::string e;
    const std::optional<TrackerSet> set = parse_tracker_set(set_text, e);
    EXPECT_TRUE(set) << e;
    SimOptions o;
    o.rate_hz = 90.0;
    o.roles = set->roles;
    o.rotation_only = set->rotation_only;
    const std::vector<TrackerSample> samples = simulate_trackers(clip, o);
    DiffusionReconstructor r(model_);
    const Outputs run = feed_and_reconstruct(r, samples, times);
    Errors out;
    int n = 0;
    size_t next = 0;
    std::array<const TrackerSample*, kPlaced.size()> newest{};
    for (size_t f = 0; f < times.size(); ++f) {
      for (; next < samples.size() && samples[next].t_ns <= times[f]; ++next)
        for (size_t k = 0; k < kPlaced.size(); ++k)
          if (samples[next].role == kPlaced[k]) newest[k] = &samples[next];
      if (f < 60) continue;
      ++n;
      for (size_t k = 0; k < kPlaced.size(); ++k)
        if (newest[k] != nullptr && newest[k]->has_position) {
          const auto j = static_cast<size_t>(features::tracker_joint(kPlaced[k]));
          out.off_tracker_max_cm = std::max(out.off_tracker_max_cm,
                                            100 * (run.poses[f].global.positions[j] - newest[k]->position_m).norm());
        }
      const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
      for (size_t s = 0; s < 2; ++s) {
        const auto foot = static_cast<size_t>(features::tracker_joint(s == 0 ? Role::LeftFoot : Role::RightFoot));
        const auto knee = static_cast<size_t>(features::tracker_joint(s == 0 ? Role::LeftKnee : Role::RightKnee));
        out.foot_deg += geodesic_angle(run.poses[f].global.rotations[foot], truth.rotations[foot]) * 90 / M_PI;
        out.knee_cm += 50 * (run.poses[f].global.positions[knee] - truth.positions[knee]).norm();
        const auto elbow = static_cast<size_t>(features::tracker_joint(s == 0 ? Role::LeftElbow : Role::RightElbow));
        out.elbow_cm += 50 * (run.poses[f].global.positions[elbow] - truth.positions[elbow]).norm();
      }
    }
    out.foot_deg /= n, out.knee_cm /= n, out.elbow_cm /= n;
    std::cout << set_text << ": hips and feet at most " << out.off_tracker_max_cm << " cm from their trackers; feet "
              << out.foot_deg << " deg from the truth; knees " << out.knee_cm << " cm; elbows " << out.elbow_cm << " cm\n";
    return out;
  };
  const Errors guessed = run_set("head,hands");
  const Errors hips = run_set("head,hands,hips");
  const Errors feet = run_set("head,hands,feet");
  const Errors knees = run_set("head,hands,feet,knees");
  const Errors feet_rot = run_set("head,hands,feet:rot");
  const Errors elbows = run_set("head,hands,elbows");
  // On the tracker but for the tracker filter's velocity prediction (it extrapolates a moving
  // tracker to the frame's time: up to about 5 mm here); the network's own hips and feet are
  // 1-4 cm off.
  EXPECT_LT(hips.off_tracker_max_cm, 0.7);
  EXPECT_LT(feet.off_tracker_max_cm, 0.7);
  EXPECT_LT(knees.off_tracker_max_cm, 0.7);
  EXPECT_LT(knees.knee_cm, 0.9 * feet.knee_cm);  // a knee tracker is the pole: the plane the leg bends in
  EXPECT_LT(feet_rot.foot_deg, 0.7 * guessed.foot_deg);
  EXPECT_LT(elbows.elbow_cm, 0.9 * guessed.elbow_cm);  // an elbow tracker is the arm's pole
}

// Issue 44 item 7: a body tracker lost mid-walk for 2 s and found again falls back to estimation
// and returns without a jump: each tracked joint's largest frame-to-frame step stays within 1.5x
// the truth's largest step.
TEST_F(DefaultModel, ALostBodyTrackerFallsBackAndReturnsWithoutAJump) {
  if (!test::have_bandai()) GTEST_SKIP() << "no " << test::bandai();
  const Motion clip = read_bvh(test::bandai() / "dataset-2" / "dataset-2_walk_normal_002.bvh");
  const auto times = frame_times(clip);
  std::string e;
  const std::optional<TrackerSet> set = parse_tracker_set("head,hands,hips,feet,knees,elbows", e);
  ASSERT_TRUE(set) << e;
  SimOptions o;
  o.rate_hz = 90.0;  // a tracker's rate, not the frames'
  o.roles = set->roles;
  std::vector<TrackerSample> samples = simulate_trackers(clip, o);
  constexpr std::int64_t kFrom = 3'000'000'000, kTo = 5'000'000'000;
  for (Role lost : {Role::Hips, Role::LeftFoot, Role::LeftKnee, Role::LeftElbow}) {
    std::vector<TrackerSample> run_samples = samples;
    for (TrackerSample& s : run_samples)
      if (s.role == lost && s.t_ns >= kFrom && s.t_ns < kTo) {
        s.valid = false;
        s.position_m = Vec3::Zero();
        s.rotation = Quat::Identity();
      }
    DiffusionReconstructor r(model_);
    const Outputs run = feed_and_reconstruct(r, run_samples, times);
    const auto j = static_cast<size_t>(features::tracker_joint(lost));
    double max_step = 0, max_truth_step = 0, max_step_at_return = 0;
    for (size_t f = 60; f < times.size(); ++f) {
      const double step = (run.poses[f].global.positions[j] - run.poses[f - 1].global.positions[j]).norm();
      const GlobalPose a = forward_kinematics(clip.skeleton, clip.frames[f - 1]);
      const GlobalPose b = forward_kinematics(clip.skeleton, clip.frames[f]);
      max_step = std::max(max_step, step);
      max_truth_step = std::max(max_truth_step, (b.positions[j] - a.positions[j]).norm());
      if (times[f] >= kTo && times[f] < kTo + 300'000'000) max_step_at_return = std::max(max_step_at_return, step);
    }
    std::cout << role_name(lost) << ": largest step " << 100 * max_step << " cm (at its return "
              << 100 * max_step_at_return << "), the truth's " << 100 * max_truth_step << " cm\n";
    EXPECT_LE(max_step, 1.5 * max_truth_step) << role_name(lost);
  }
}

TEST_F(DefaultModel, UserHeightScalesTheBody) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto times = frame_times(clip);
  DiffusionReconstructor r(model_);
  const double model_h = r.model_height();
  r.set_head_height_m(model_h * 1.2);
  auto samples = trackers(clip);
  for (TrackerSample& s : samples) s.position_m *= 1.2;  // a user 20% taller
  const Outputs run = feed_and_reconstruct(r, samples, times);
  const auto head = static_cast<size_t>(features::kHead);
  const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames.back());
  EXPECT_NEAR(run.poses.back().global.positions[head].y(), 1.2 * truth.positions[head].y(), 0.03);
  EXPECT_NEAR(r.skeleton().offsets[2].norm(), 1.2 * model_->skeleton.offsets[2].norm(), 1e-9);
  // Feet stay on the floor (the floor does not scale away).
  const double toe = std::min(run.poses.back().global.positions[features::kToesL].y(),
                              run.poses.back().global.positions[features::kToesR].y());
  EXPECT_LT(toe, 0.12);
}

namespace {

// Mean norm of the third difference of every body joint's position x fps^3 (the jitter of
// docs/conventions.md), over frames [first, poses.size()).
double jitter_m_s3(const std::vector<GlobalPose>& poses, double fps, size_t first = 0) {
  double sum = 0;
  int n = 0;
  for (size_t f = std::max<size_t>(first, 3); f < poses.size(); ++f)
    for (size_t j = 1; j < poses[f].positions.size(); ++j) {
      sum += (poses[f].positions[j] - 3.0 * poses[f - 1].positions[j] + 3.0 * poses[f - 2].positions[j] -
              poses[f - 3].positions[j]).norm() * fps * fps * fps;
      ++n;
    }
  return sum / n;
}

// The simulator at the clip's frame rate (seed 3), with 2 mm / 1 degree tracker noise when `noisy`.
SimOptions sim_at_clip_rate(const Motion& clip, bool noisy) {
  SimOptions o;
  o.rate_hz = clip.fps();
  o.seed = 3;
  if (noisy) {
    o.position_noise_mm = 2.0;
    o.rotation_noise_deg = 1.0;
  }
  return o;
}

std::vector<GlobalPose> globals(const Outputs& run) {
  std::vector<GlobalPose> out;
  for (const BodyPose& p : run.poses) out.push_back(p.global);
  return out;
}

// The mean third difference of joint j from 0.5 s on (m/s^3 at the clip's rate).
double joint_jitter(const Outputs& run, size_t j, double fps) {
  double sum = 0;
  int n = 0;
  for (size_t f = 18; f < run.poses.size(); ++f) {
    const auto p = [&](size_t k) { return run.poses[k].global.positions[j]; };
    sum += (p(f) - 3.0 * p(f - 1) + 3.0 * p(f - 2) - p(f - 3)).norm() * std::pow(fps, 3);
    ++n;
  }
  return sum / n;
}

// walk_60 through two reconstructors of `model`, options `a` and `b`, its trackers at the clip's
// rate, with 2 mm / 1 degree noise or clean; and the mean distance of `joints` to the truth.
struct TwoRuns {
  Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  Outputs a, b;
  TwoRuns(const std::shared_ptr<const inference::Model>& model, bool noisy, const DiffusionOptions& oa,
          const DiffusionOptions& ob) {
    const auto times = frame_times(clip);
    const auto samples = simulate_trackers(clip, sim_at_clip_rate(clip, noisy));
    DiffusionReconstructor ra(model, oa), rb(model, ob);
    a = feed_and_reconstruct(ra, samples, times);
    b = feed_and_reconstruct(rb, samples, times);
  }
  [[nodiscard]] double error(const Outputs& run, std::initializer_list<int> joints) const {
    double sum = 0;
    for (size_t f = 0; f < run.poses.size(); ++f) {
      const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
      for (const int j : joints)
        sum += (run.poses[f].global.positions[static_cast<size_t>(j)] - truth.positions[static_cast<size_t>(j)]).norm();
    }
    return sum / static_cast<double>(run.poses.size() * joints.size());
  }
  [[nodiscard]] double jitter(const Outputs& run, std::initializer_list<const char*> joints) const {
    double sum = 0;
    for (const char* name : joints) sum += joint_jitter(run, static_cast<size_t>(clip.skeleton.find(name)), clip.fps());
    return sum / static_cast<double>(joints.size());
  }
};

// The three noisy-tracker measures off (the behaviour before them).
DiffusionOptions without_noise_measures() {
  DiffusionOptions o;
  o.filter.anchor_cutoff_hz = 0.0;
  o.filter.hand_reach_slack_m = 0.0;
  o.filter.arm_soft_zone_m = 0.0;
  return o;
}

}  // namespace

// Issue 10 item 3: on clean trackers (no noise) the Head joint is on the head tracker within
// 1 mm and 0.5 degrees and the hands within 1 mm, every frame: the tracker filter must not put
// its lag between the tracked joints and their trackers. (Samples at the clip's 30 Hz, as
// bodyd-eval feeds them: the simulator's 90 Hz samples interpolate the 30 Hz clip linearly, and
// its kinks read as about a millimetre of noise, docs/model.md.)
TEST_F(DefaultModel, HeadAndHandsExactlyOnCleanTrackers) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto samples = trackers(clip);
  const auto times = frame_times(clip);
  DiffusionReconstructor r(model_);
  const Outputs run = feed_and_reconstruct(r, samples, times);
  double head_m = 0, head_deg = 0, hand_m = 0;
  for (size_t f = 0; f < times.size(); ++f) {
    const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
    const auto head = static_cast<size_t>(features::kHead);
    head_m = std::max(head_m, (run.poses[f].global.positions[head] - truth.positions[head]).norm());
    head_deg = std::max(head_deg, geodesic_angle(run.poses[f].global.rotations[head], truth.rotations[head]) * 180 / M_PI);
    for (int j : {features::kHandL, features::kHandR})
      hand_m = std::max(hand_m, (run.poses[f].global.positions[static_cast<size_t>(j)] -
                                 truth.positions[static_cast<size_t>(j)]).norm());
  }
  EXPECT_LT(head_m, 0.001);
  EXPECT_LT(head_deg, 0.5);
  EXPECT_LT(hand_m, 0.001);
}

// Issue 10 item 4: 2 mm / 1 degree tracker noise (30 Hz) must not shake the body: the output's
// jitter stays within 2.5 x the clean run's (the tracked joints on the raw noisy samples gave
// about 4 x) and the mean joint error grows by less than 1 cm. The body filter, which smooths
// the clean run as much as the noisy one, is off here: this is the tracker filter's test.
TEST_F(DefaultModel, TrackerNoiseDoesNotShakeTheBody) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto times = frame_times(clip);
  const auto clean = simulate_trackers(clip, sim_at_clip_rate(clip, false));
  const auto noisy = simulate_trackers(clip, sim_at_clip_rate(clip, true));
  DiffusionOptions no_body_filter;
  no_body_filter.body_filter.enabled = false;
  DiffusionReconstructor a(model_, no_body_filter), b(model_, no_body_filter);
  const Outputs ra = feed_and_reconstruct(a, clean, times), rb = feed_and_reconstruct(b, noisy, times);
  // From 0.5 s on: the filter measures the noise over its first samples.
  const double j_clean = jitter_m_s3(globals(ra), clip.fps(), 15), j_noisy = jitter_m_s3(globals(rb), clip.fps(), 15);
  EXPECT_LT(j_noisy, 2.5 * j_clean) << "clean " << j_clean << " noisy " << j_noisy;
  double err_clean = 0, err_noisy = 0;
  for (size_t f = 0; f < times.size(); ++f) {
    const GlobalPose truth = forward_kinematics(clip.skeleton, clip.frames[f]);
    for (size_t j = 1; j < truth.positions.size(); ++j) {
      err_clean += (ra.poses[f].global.positions[j] - truth.positions[j]).norm();
      err_noisy += (rb.poses[f].global.positions[j] - truth.positions[j]).norm();
    }
  }
  const double n = static_cast<double>(times.size() * (clip.skeleton.names.size() - 1));
  EXPECT_LT(err_noisy / n - err_clean / n, 0.01);
}

// Issue 18 item 4: the body moves the whole of itself with the Head joint, so a noisy head
// tracker's filtered noise shook every joint. The head correction (OneEuroOptions::
// head_correction_cutoff_hz) puts the Head joint on the network's head plus the low-passed
// difference to the tracker instead: the Hips shake less than with the correction made
// unfiltered (a cutoff far above the frame rate, the behaviour before it), and the Head still
// follows its tracker within a centimetre. On clean trackers it changes nothing
// (HeadAndHandsExactlyOnCleanTrackers).
TEST_F(DefaultModel, ANoisyHeadTrackerDoesNotShakeTheHips) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto times = frame_times(clip);
  const auto noisy = simulate_trackers(clip, sim_at_clip_rate(clip, true));
  DiffusionOptions corrected, unfiltered;
  unfiltered.filter.head_correction_cutoff_hz = 1e4;
  DiffusionReconstructor a(model_, corrected), b(model_, unfiltered);
  const Outputs ra = feed_and_reconstruct(a, noisy, times), rb = feed_and_reconstruct(b, noisy, times);
  const auto hips = static_cast<size_t>(features::kHips), head = static_cast<size_t>(features::kHead);
  const double with = joint_jitter(ra, hips, clip.fps()), without = joint_jitter(rb, hips, clip.fps());
  EXPECT_LT(with, 0.92 * without) << "Hips jitter with the correction " << with << ", unfiltered " << without;
  double head_err = 0;
  for (size_t f = 0; f < times.size(); ++f)
    head_err += (ra.poses[f].global.positions[head] -
                 forward_kinematics(clip.skeleton, clip.frames[f]).positions[head]).norm();
  EXPECT_LT(head_err / static_cast<double>(times.size()), 0.01);
}

// Issue 18 item 4: the smoothed anchor (OneEuroOptions::anchor_cutoff_hz), the reach slack
// (hand_reach_slack_m) and the arms' soft reach (arm_soft_zone_m) act on noisy trackers only; on
// clean ones every joint of every frame is what it is with all three off.
TEST_F(DefaultModel, TheNoisyTrackerMeasuresLeaveCleanTrackersAsTheyWere) {
  DiffusionOptions strong;
  strong.filter.anchor_cutoff_hz = 1.0;
  strong.filter.hand_reach_slack_m = 0.2;
  strong.filter.arm_soft_zone_m = 0.05;
  const TwoRuns runs(model_, false, without_noise_measures(), strong);
  ASSERT_EQ(runs.a.poses.size(), runs.b.poses.size());
  for (size_t f = 0; f < runs.a.poses.size(); ++f)
    for (size_t j = 0; j < runs.a.poses[f].global.positions.size(); ++j)
      ASSERT_EQ(runs.a.poses[f].global.positions[j], runs.b.poses[f].global.positions[j]) << "frame " << f << " joint " << j;
}

// Issue 18 item 4: with the defaults a noisy body shakes less than with the three measures off,
// joint for joint over the whole body (the held-out styles: 2.34x the truth's jitter -> 1.89x
// with the shipped tcnmlp-v1 model, 2.32x -> 1.84x with the mlpwin-v1 model they were chosen on,
// docs/models.md), while the Head stays within a centimetre of the truth and the hands within
// 1.5 cm more than before (the slack lets a hand at full reach fall short). On this one short
// clip the shipped model's body jitter falls by 7.5% (0.925x); 0.95 leaves room for a retrained
// model and still fails when the measures do nothing.
TEST_F(DefaultModel, TheNoisyTrackerMeasuresCalmTheWholeBody) {
  const TwoRuns runs(model_, true, without_noise_measures(), DiffusionOptions{});
  const std::initializer_list<const char*> body = {"Hips", "Spine", "Chest", "Neck", "Head", "UpperArm_L", "UpperArm_R",
                                                   "LowerArm_L", "LowerArm_R", "UpperLeg_L", "UpperLeg_R"};
  const double before = runs.jitter(runs.a, body), after = runs.jitter(runs.b, body);
  EXPECT_LT(after, 0.95 * before) << "body jitter with the defaults " << after << ", with the measures off " << before;
  EXPECT_LT(runs.error(runs.b, {features::kHead}), 0.01);
  EXPECT_LT(runs.error(runs.b, {features::kHandL, features::kHandR}),
            runs.error(runs.a, {features::kHandL, features::kHandR}) + 0.015);
}

// Issue 18 item 4: each window is expressed in the frame of its newest head, so a noisy head
// tracker moved that frame, and the whole body with it, frame by frame. With the smoothed anchor
// (the other two measures at their defaults in both runs) the trunk shakes less.
TEST_F(DefaultModel, TheSmoothedAnchorKeepsANoisyHeadFromShakingTheTrunk) {
  DiffusionOptions off;
  off.filter.anchor_cutoff_hz = 0.0;
  const TwoRuns runs(model_, true, off, DiffusionOptions{});
  for (const char* name : {"Hips", "Spine", "Chest"}) {
    const double without = runs.jitter(runs.a, {name}), with = runs.jitter(runs.b, {name});
    EXPECT_LT(with, 0.95 * without) << name << ": with the anchor " << with << ", without " << without;
  }
}

// Issue 18 item 4: near a straight arm two-bone IK turns a noisy hand's millimetres into
// centimetres at the elbow; the soft reach (arm_soft_zone_m) calms the elbows, and the hands'
// mean error (the noise and the filter's lag in both runs) grows by under 2 mm.
TEST_F(DefaultModel, SoftArmsKeepANoisyHandFromShakingTheElbow) {
  DiffusionOptions off, on;
  off.filter.arm_soft_zone_m = 0.0;
  on.filter.arm_soft_zone_m = 0.02;
  const TwoRuns runs(model_, true, off, on);
  const double without = runs.jitter(runs.a, {"LowerArm_L", "LowerArm_R"}),
               with = runs.jitter(runs.b, {"LowerArm_L", "LowerArm_R"});
  EXPECT_LT(with, 0.95 * without) << "elbow jitter with the soft reach " << with << ", without " << without;
  EXPECT_LT(runs.error(runs.b, {features::kHandL, features::kHandR}),
            runs.error(runs.a, {features::kHandL, features::kHandR}) + 0.002);
}

// Issue 10 item 4: a hand back from a gap moves to its tracker without a jump: on every frame
// its motion differs from the real hand's by less than 3 cm (the hand neither freezes while the
// body walks on nor snaps back), and it is on its tracker again within 0.5 s.
TEST_F(DefaultModel, AHandBackFromAGapEasesToItsTrackerWithoutAJump) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  auto samples = trackers(clip);
  const auto times = frame_times(clip);
  // The right hand is lost from 0.5 s to 1.0 s.
  constexpr std::int64_t kLost = 500'000'000, kBack = 1'000'000'000;
  for (TrackerSample& s : samples)
    if (s.role == Role::RightHand && s.t_ns >= kLost && s.t_ns < kBack) s.valid = false;
  DiffusionReconstructor r(model_);
  const Outputs run = feed_and_reconstruct(r, samples, times);
  const auto hand = static_cast<size_t>(features::kHandR);
  double worst = 0;
  std::optional<std::int64_t> on_tracker_ns;
  for (size_t f = 1; f < times.size(); ++f) {
    const GlobalPose a = forward_kinematics(clip.skeleton, clip.frames[f - 1]);
    const GlobalPose b = forward_kinematics(clip.skeleton, clip.frames[f]);
    const Vec3 step = run.poses[f].global.positions[hand] - run.poses[f - 1].global.positions[hand];
    worst = std::max(worst, (step - (b.positions[hand] - a.positions[hand])).norm());
    if (times[f] >= kBack && !on_tracker_ns && (run.poses[f].global.positions[hand] - b.positions[hand]).norm() < 0.002)
      on_tracker_ns = times[f];
  }
  EXPECT_LT(worst, 0.03) << "worst " << worst;
  ASSERT_TRUE(on_tracker_ns.has_value()) << "the hand never got back onto its tracker";
  EXPECT_LE(*on_tracker_ns - kBack, 500'000'000);
}

namespace {

// A synthetic stream long enough for 1,100 poses at 30 Hz: the head sways, the hands swing.
std::vector<TrackerSample> long_stream(int frames, std::int64_t dt_ns) {
  std::vector<TrackerSample> out;
  for (int f = 0; f < frames; ++f) {
    const double t = f * static_cast<double>(dt_ns) * 1e-9;
    for (Role role : kXrRoles) {
      TrackerSample s;
      s.t_ns = f * dt_ns;
      s.role = role;
      s.valid = true;
      const double side = role == Role::LeftHand ? 1.0 : -1.0;
      s.position_m = role == Role::Head ? Vec3(0.05 * std::sin(t), 1.55, 0.4 * t)
                                        : Vec3(0.25 * side, 0.9 + 0.1 * std::sin(2 * t + side), 0.4 * t + 0.2 * std::cos(2 * t));
      s.rotation = quat_from_yaw(0.2 * std::sin(0.5 * t));
      out.push_back(s);
    }
  }
  return out;
}

}  // namespace

// Issue 11, item 1: one extreme but finite (or non-finite) tracker value used to break the stream
// until restart. Now it is refused and counted, and the next 1,000 poses equal a run without it.
TEST(Diffusion, ABadSampleMidStreamNeverPoisonsLaterPoses) {
  constexpr std::int64_t kDt = 33'333'333;
  constexpr int kFrames = 1100;
  const auto clean = long_stream(kFrames, kDt);
  std::vector<TrackerSample> dirty;
  const double nan = std::nan("");
  for (const TrackerSample& s : clean) {
    dirty.push_back(s);
    if (s.t_ns == 50 * kDt && s.role == Role::RightHand) {
      // Between frames 50 and 51, one bad sample per kind.
      TrackerSample b = s;
      b.t_ns = s.t_ns + kDt / 3;
      b.role = Role::LeftHand;
      b.position_m = Vec3(1e300, 0.9, 0);  // the sed: left hand x = 1e300
      dirty.push_back(b);
      b.role = Role::Head;
      b.position_m = Vec3(0, nan, 0);
      dirty.push_back(b);
      b.role = Role::RightHand;
      b.position_m = Vec3(0, 1e5, 0);
      dirty.push_back(b);
      b.t_ns += 1;
      b.position_m = Vec3(0, 1, 0);
      b.rotation = Quat(0, 0, 0, 7);  // not unit length
      dirty.push_back(b);
    }
  }
  std::vector<std::int64_t> times;
  for (int f = 0; f < kFrames; ++f) times.push_back(f * kDt);
  const auto model = tiny_model();
  DiffusionReconstructor a(model), b(model);
  const Outputs ra = feed_and_reconstruct(a, clean, times);
  const Outputs rb = feed_and_reconstruct(b, dirty, times);
  EXPECT_EQ(a.refused_samples(), 0);
  EXPECT_EQ(b.refused_samples(), 4);
  EXPECT_EQ(b.refused_outputs(), 0);
  ASSERT_EQ(ra.poses.size(), rb.poses.size());
  int compared = 0;
  for (size_t f = 51; f < ra.poses.size(); ++f, ++compared)
    for (size_t j = 0; j < ra.poses[f].global.positions.size(); ++j) {
      ASSERT_TRUE(rb.poses[f].global.positions[j].allFinite()) << "frame " << f << " joint " << j;
      ASSERT_NEAR((ra.poses[f].global.positions[j] - rb.poses[f].global.positions[j]).norm(), 0.0, 1e-6)
          << "frame " << f << " joint " << j;
    }
  EXPECT_GE(compared, 1000);
}

// The online loop keeps each emitted frame's world entries and rotates them into every later
// window's canonical frame (features::encode_world_entries) instead of encoding the pose again:
// the same features as encode_pose, for every frame of a walk in the frames of heads that face
// elsewhere and stand elsewhere, contacts included.
TEST(Features, WorldEntriesGiveWhatEncodePoseGives) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const auto head = static_cast<size_t>(features::kHead);
  std::vector<float> a(features::kDim), b(features::kDim);
  features::WorldEntries world;
  int compared = 0;
  for (size_t f = 0; f < clip.frames.size(); f += 7) {
    const GlobalPose g = forward_kinematics(clip.skeleton, clip.frames[f]);
    features::world_entries(g, world);
    for (size_t h = 0; h < clip.frames.size(); h += 13) {
      const GlobalPose gh = forward_kinematics(clip.skeleton, clip.frames[h]);
      for (double turn : {0.0, 2.0, -2.9}) {
        const Quat q = Quat(Eigen::AngleAxisd(turn, Vec3::UnitY())) * gh.rotations[head];
        const features::Canonical c = features::canonical_from_head(gh.positions[head] + Vec3(0.4 * turn, 0, -1), q);
        const std::array<bool, 2> contact{f % 2 == 0, f % 3 == 0};
        features::encode_pose(g, contact, c, features::Frame(a.data(), a.size()));
        features::encode_world_entries(world, contact, c, features::Frame(b.data(), b.size()));
        for (int k = 0; k < features::kDim; ++k)
          ASSERT_NEAR(a[static_cast<size_t>(k)], b[static_cast<size_t>(k)], 1e-6) << "frame " << f << " entry " << k;
        ++compared;
      }
    }
  }
  EXPECT_GT(compared, 20);
}

// DiffusionOptions::leg_position_blend: a frame whose ankle positions sit a few centimetres from
// where its rotations put them (nearer the hips, so the target is reachable): blend 1 puts each
// ankle on its predicted position, 0.5 halfway, 0 leaves the pose alone; the feet keep their
// rotations and nothing but the legs moves.
TEST(Diffusion, LegsBendTowardThePredictedAnkles) {
  const Motion clip = read_bvh(test::fixtures() / "walk_60.bvh");
  const Skeleton& sk = clip.skeleton;
  ASSERT_EQ(features::check_skeleton(sk), "");
  GlobalPose truth;
  forward_kinematics(sk, clip.frames[10], truth);
  const auto head = static_cast<size_t>(features::kHead);
  const features::Canonical canon = features::canonical_from_head(truth.positions[head], truth.rotations[head]);
  std::array<float, features::kDim> frame{};
  features::encode_pose(truth, {false, false}, canon, frame);
  const std::array<std::optional<TwoBoneChain>, 2> legs = {
      find_two_bone_chain(sk, "UpperLeg_L", "LowerLeg_L", "Foot_L"),
      find_two_bone_chain(sk, "UpperLeg_R", "LowerLeg_R", "Foot_R")};
  ASSERT_TRUE(legs[0] && legs[1]);
  const Vec3 offsets[2] = {Vec3(0.03, 0.05, 0.02), Vec3(-0.02, 0.04, -0.03)};
  for (size_t s = 0; s < 2; ++s) {
    const auto end = static_cast<size_t>(legs[s]->end);
    features::encode_joint(legs[s]->end, truth.positions[end] + offsets[s], truth.rotations[end], canon, frame);
  }
  for (const double blend : {0.0, 0.5, 1.0}) {
    Pose pose = clip.frames[10];
    GlobalPose global = truth;
    bend_legs_toward_predicted_ankles(sk, legs, frame, canon, blend, pose, global);
    for (size_t s = 0; s < 2; ++s) {
      const auto end = static_cast<size_t>(legs[s]->end);
      EXPECT_LT((global.positions[end] - (truth.positions[end] + blend * offsets[s])).norm(), 1e-5) << blend;
      EXPECT_LT(global.rotations[end].angularDistance(truth.rotations[end]), 1e-5) << blend;
    }
    for (const char* joint : {"Hips", "Head", "Hand_L", "Hand_R", "UpperLeg_L", "UpperLeg_R"}) {
      const auto j = static_cast<size_t>(sk.find(joint));
      EXPECT_LT((global.positions[j] - truth.positions[j]).norm(), 1e-9) << joint << " " << blend;
    }
  }
  // The option is checked with the foot lock's.
  DiffusionOptions bad;
  for (const double blend : {std::numeric_limits<double>::quiet_NaN(), -0.1, 1.5}) {
    bad.leg_position_blend = blend;
    EXPECT_NE(validate_foot_lock(bad).find("leg_position_blend"), std::string::npos) << blend;
  }
}
