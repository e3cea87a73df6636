#include "bodyd/simulators/tracker_sim.h"

#include "../test_paths.h"
#include "bodyd/test/tracker_sample.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>

using namespace bodyd;
using bodyd::test::same_samples;

namespace {

const Motion& walk() {
  static const Motion m = read_bvh(test::fixtures() / "walk_60.bvh");
  return m;
}

// The clip's frames repeated until it is `seconds` long (for statistics).
Motion long_motion(double seconds) {
  Motion m = walk();
  const auto base = m.frames;
  while (static_cast<double>(m.frames.size()) * m.frame_time_s < seconds)
    m.frames.insert(m.frames.end(), base.begin(), base.end());
  return m;
}

// Global rotation matrix and position of one joint, computed here from the local
// transforms by walking the chain to the root with rotation matrices (independent of
// bodyd::forward_kinematics).
struct Global {
  Mat3 R;
  Vec3 p;
};
Global chain_fk(const Skeleton& sk, const Pose& pose, int joint) {
  std::vector<int> chain;
  for (int j = joint; j >= 0; j = sk.parents[static_cast<size_t>(j)]) chain.push_back(j);
  Global g{Mat3::Identity(), Vec3::Zero()};
  for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
    const auto j = static_cast<size_t>(*it);
    g.p = g.p + g.R * pose.local_translations[j];
    g.R = g.R * pose.local_rotations[j].toRotationMatrix();
  }
  return g;
}

std::vector<TrackerSample> of_role(const std::vector<TrackerSample>& all, Role r) {
  std::vector<TrackerSample> out;
  for (const auto& s : all)
    if (s.role == r) out.push_back(s);
  return out;
}

double angle_deg(const Mat3& a, const Quat& b) {
  return geodesic_angle(Quat(a), b) * 180.0 / M_PI;
}

struct Stats {
  double n = 0, sum = 0, sum2 = 0;
  void add(double x) {
    n += 1;
    sum += x;
    sum2 += x * x;
  }
  double mean() const { return sum / n; }
  double std() const { return std::sqrt(sum2 / n - mean() * mean()); }
};

// Max distance (mm) and angle (deg) between the no-noise samples and the independent
// FK of the clip: at a sample within 1 us of a frame time the frame's FK itself,
// elsewhere the FK of the two neighbouring frames interpolated at the sample's time.
struct MaxError {
  double at_frames_mm = 0, at_frames_deg = 0, between_mm = 0, between_deg = 0;
  int at_frames = 0, between = 0;
};
MaxError max_error(const Motion& m, double rate_hz) {
  SimOptions opt;
  opt.rate_hz = rate_hz;
  const auto samples = simulate_trackers(m, opt);
  MaxError e;
  for (Role r : kXrRoles) {
    const int joint = m.skeleton.find(role_joint_name(r));
    std::vector<Global> fk;
    for (const Pose& pose : m.frames) fk.push_back(chain_fk(m.skeleton, pose, joint));
    for (const auto& s : of_role(samples, r)) {
      EXPECT_TRUE(s.valid);
      const double f = static_cast<double>(s.t_ns) * 1e-9 / m.frame_time_s;
      const auto k = static_cast<size_t>(std::lround(f));
      if (std::abs(f - static_cast<double>(k)) * m.frame_time_s <= 1e-6) {
        e.at_frames_mm = std::max(e.at_frames_mm, (fk[k].p - s.position_m).norm() * 1e3);
        e.at_frames_deg = std::max(e.at_frames_deg, angle_deg(fk[k].R, s.rotation));
        ++e.at_frames;
      } else {
        const auto i = static_cast<size_t>(std::floor(f));
        const double a = f - static_cast<double>(i);
        const Vec3 p = (1 - a) * fk[i].p + a * fk[i + 1].p;
        const Quat q = Quat(fk[i].R).slerp(a, Quat(fk[i + 1].R));
        e.between_mm = std::max(e.between_mm, (p - s.position_m).norm() * 1e3);
        e.between_deg = std::max(e.between_deg, angle_deg(q.toRotationMatrix(), s.rotation));
        ++e.between;
      }
    }
  }
  return e;
}

}  // namespace

TEST(TrackerSim, NoNoiseMatchesIndependentFkAtFrameTimes) {
  const Motion& m = walk();
  // At the data's own rate and at three samples per frame every frame time is sampled.
  for (double rate : {m.fps(), 3.0 * m.fps()}) {
    const MaxError e = max_error(m, rate);
    EXPECT_EQ(e.at_frames, 3 * m.frame_count()) << "rate " << rate;
    EXPECT_LT(e.at_frames_mm, 1.0) << "rate " << rate;
    EXPECT_LT(e.at_frames_deg, 0.05) << "rate " << rate;
    EXPECT_LT(e.between_mm, 1.0) << "rate " << rate;
    std::cout << "walk_60 at " << rate << " Hz: max error at frame times " << e.at_frames_mm << " mm, "
              << e.at_frames_deg << " deg\n";
  }
}

TEST(TrackerSim, InterpolatesLinearlyAndSlerpsBetweenFrames) {
  const Motion& m = walk();
  SimOptions opt;
  opt.rate_hz = 3.0 / m.frame_time_s;  // exactly three samples per frame
  const auto hand = of_role(simulate_trackers(m, opt), Role::LeftHand);
  const int joint = m.skeleton.find("Hand_L");
  ASSERT_EQ(hand.size(), static_cast<size_t>(3 * (m.frame_count() - 1) + 1));
  double max_mm = 0, max_deg = 0, moved_mm = 0;
  for (int k = 0; k + 1 < m.frame_count(); ++k) {
    const Global a = chain_fk(m.skeleton, m.frames[static_cast<size_t>(k)], joint);
    const Global b = chain_fk(m.skeleton, m.frames[static_cast<size_t>(k + 1)], joint);
    for (int i = 1; i < 3; ++i) {
      const double t = i / 3.0;
      const TrackerSample& s = hand[static_cast<size_t>(3 * k + i)];
      max_mm = std::max(max_mm, ((1 - t) * a.p + t * b.p - s.position_m).norm() * 1e3);
      max_deg = std::max(max_deg, angle_deg(Quat(a.R).slerp(t, Quat(b.R)).toRotationMatrix(), s.rotation));
    }
    moved_mm = std::max(moved_mm, (a.p - b.p).norm() * 1e3);
  }
  EXPECT_LT(max_mm, 0.01);
  EXPECT_LT(max_deg, 1e-3);
  EXPECT_GT(moved_mm, 5.0);  // the hand does move between frames, so the check has teeth
}

TEST(TrackerSim, SortedWithTheRequestedRatesPerRole) {
  const Motion& m = walk();
  const double duration_s = (m.frame_count() - 1) * m.frame_time_s;
  SimOptions opt;
  opt.rate_hz = 90;
  opt.role_rate_hz[static_cast<size_t>(Role::Head)] = 72;
  opt.role_rate_hz[static_cast<size_t>(Role::RightHand)] = 120;
  const auto samples = simulate_trackers(m, opt);
  for (size_t i = 1; i < samples.size(); ++i) ASSERT_LE(samples[i - 1].t_ns, samples[i].t_ns);
  const std::map<Role, double> rate{{Role::Head, 72.0}, {Role::LeftHand, 90.0}, {Role::RightHand, 120.0}};
  for (const auto& [role, hz] : rate) {
    const auto v = of_role(samples, role);
    EXPECT_EQ(v.size(), static_cast<size_t>(std::floor(duration_s * hz)) + 1) << role_name(role);
    EXPECT_EQ(v.front().t_ns, 0);
    const double mean_dt_s = static_cast<double>(v.back().t_ns - v.front().t_ns) * 1e-9 /
                             static_cast<double>(v.size() - 1);
    EXPECT_NEAR(1.0 / mean_dt_s, hz, 1e-6 * hz) << role_name(role);
    EXPECT_LE(v.back().t_ns, std::llround(duration_s * 1e9));
  }
}

TEST(TrackerSim, SameSeedSameOutputOtherSeedDifferent) {
  SimOptions opt;
  opt.position_noise_mm = 3;
  opt.rotation_noise_deg = 2;
  opt.jitter_ms = 1;
  opt.latency_ms = 15;
  opt.dropout_rate_hz = 2;
  opt.seed = 42;
  const auto a = simulate_trackers(walk(), opt);
  const auto b = simulate_trackers(walk(), opt);
  ASSERT_TRUE(same_samples(a, b));
  opt.seed = 43;
  const auto c = simulate_trackers(walk(), opt);
  ASSERT_EQ(a.size(), c.size());
  size_t diff_pos = 0, diff_t = 0, diff_valid = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    diff_t += a[i].t_ns != c[i].t_ns;
    diff_valid += a[i].valid != c[i].valid;
    diff_pos += a[i].valid && c[i].valid && a[i].position_m != c[i].position_m;
  }
  EXPECT_GT(diff_t, a.size() / 2);
  EXPECT_GT(diff_pos, a.size() / 4);
  EXPECT_GT(diff_valid, 0u);
}

TEST(TrackerSim, EffectsAndRolesUseIndependentRandomStreams) {
  SimOptions opt;
  opt.position_noise_mm = 3;
  const auto base = of_role(simulate_trackers(walk(), opt), Role::LeftHand);
  // Changing the head's rate or turning on jitter must not change the hand's position noise.
  opt.role_rate_hz[static_cast<size_t>(Role::Head)] = 50;
  opt.jitter_ms = 2;
  const auto other = of_role(simulate_trackers(walk(), opt), Role::LeftHand);
  ASSERT_EQ(base.size(), other.size());
  for (size_t i = 0; i < base.size(); ++i) ASSERT_EQ(base[i].position_m, other[i].position_m);
}

TEST(TrackerSim, NoiseHasTheRequestedStandardDeviation) {
  const Motion m = long_motion(30.0);
  SimOptions clean_opt;
  clean_opt.rate_hz = 200;
  SimOptions noisy_opt = clean_opt;
  noisy_opt.position_noise_mm = 4.0;
  noisy_opt.rotation_noise_deg = 1.5;
  const auto clean = simulate_trackers(m, clean_opt);
  const auto noisy = simulate_trackers(m, noisy_opt);
  ASSERT_EQ(clean.size(), noisy.size());
  std::array<Stats, 3> pos, rot;
  for (size_t i = 0; i < clean.size(); ++i) {
    ASSERT_EQ(clean[i].t_ns, noisy[i].t_ns);
    const Vec3 dp_mm = (noisy[i].position_m - clean[i].position_m) * 1e3;
    const Vec3 dr_deg = axis_angle_from_quat(noisy[i].rotation * clean[i].rotation.conjugate()) * 180.0 / M_PI;
    for (int k = 0; k < 3; ++k) {
      pos[static_cast<size_t>(k)].add(dp_mm[k]);
      rot[static_cast<size_t>(k)].add(dr_deg[k]);
    }
  }
  EXPECT_GT(pos[0].n, 15000);
  std::cout << "position noise std (mm, requested 4): " << pos[0].std() << " " << pos[1].std() << " "
            << pos[2].std() << "; rotation (deg, requested 1.5): " << rot[0].std() << " " << rot[1].std() << " "
            << rot[2].std() << "\n";
  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE(k);
    // ~18000 draws per axis: the standard error of the std is about 0.5%.
    EXPECT_NEAR(pos[static_cast<size_t>(k)].std(), 4.0, 0.1);
    EXPECT_NEAR(pos[static_cast<size_t>(k)].mean(), 0.0, 0.1);
    EXPECT_NEAR(rot[static_cast<size_t>(k)].std(), 1.5, 0.04);
    EXPECT_NEAR(rot[static_cast<size_t>(k)].mean(), 0.0, 0.04);
  }
}

TEST(TrackerSim, LatencyShiftsAndJitterSpreadsTimestamps) {
  const Motion m = long_motion(20.0);
  SimOptions opt;
  const auto base = simulate_trackers(m, opt);
  opt.latency_ms = 25;
  const auto late = simulate_trackers(m, opt);
  ASSERT_EQ(base.size(), late.size());
  for (size_t i = 0; i < base.size(); ++i) {
    ASSERT_EQ(late[i].t_ns, base[i].t_ns + 25'000'000);
    ASSERT_EQ(late[i].position_m, base[i].position_m);  // same pose, only later
  }
  opt.jitter_ms = 1.0;
  const auto jit = simulate_trackers(m, opt);
  ASSERT_EQ(base.size(), jit.size());
  for (Role r : kXrRoles) {
    const auto b = of_role(base, r), j = of_role(jit, r);
    Stats d;
    for (size_t i = 0; i < b.size(); ++i) {
      d.add(static_cast<double>(j[i].t_ns - b[i].t_ns - 25'000'000) * 1e-6);
      ASSERT_EQ(j[i].position_m, b[i].position_m);  // the pose is that of the true time
    }
    EXPECT_NEAR(d.std(), 1.0, 0.05) << role_name(r);
    EXPECT_NEAR(d.mean(), 0.0, 0.05) << role_name(r);
  }
  // Jitter larger than the period is clamped: time still increases within each role.
  opt.jitter_ms = 50;
  const auto wild = simulate_trackers(m, opt);
  for (Role r : kXrRoles) {
    const auto v = of_role(wild, r);
    for (size_t i = 1; i < v.size(); ++i) ASSERT_LT(v[i - 1].t_ns, v[i].t_ns) << role_name(r) << " " << i;
  }
}

TEST(TrackerSim, DropoutFractionAndEpisodeRateMatchTheModel) {
  const Motion m = long_motion(1000.0);
  SimOptions opt;
  opt.rate_hz = 90;
  opt.dropout_rate_hz = 1.0;
  opt.dropout_mean_ms = 200;
  const double expected = opt.dropout_fraction();
  EXPECT_NEAR(expected, 0.2 / 1.2, 1e-12);
  const auto samples = simulate_trackers(m, opt);
  for (Role r : kXrRoles) {
    const auto v = of_role(samples, r);
    size_t invalid = 0, episodes = 0;
    for (size_t i = 0; i < v.size(); ++i) {
      if (!v[i].valid) {
        ++invalid;
        if (i == 0 || v[i - 1].valid) ++episodes;
        EXPECT_EQ(v[i].position_m, Vec3::Zero());
      }
    }
    const double fraction = static_cast<double>(invalid) / static_cast<double>(v.size());
    if (r == Role::Head) {
      EXPECT_EQ(invalid, 0u);
      continue;
    }
    // About 830 episodes per hand: the fraction's standard error is about 4% relative.
    EXPECT_NEAR(fraction, expected, 0.15 * expected) << role_name(r);
    // Episodes per second of tracked time; episodes shorter than a sample period
    // (1 - exp(-11.1/200) = 5% of them) are missed by the sampling.
    const double tracked_s = static_cast<double>(v.size() - invalid) / opt.rate_hz;
    EXPECT_NEAR(static_cast<double>(episodes) / tracked_s, 0.95 * opt.dropout_rate_hz, 0.12) << role_name(r);
    std::cout << role_name(r) << ": invalid fraction " << fraction << " (expected " << expected << "), "
              << episodes << " episodes\n";
  }
  // The two hands drop out independently.
  const auto l = of_role(samples, Role::LeftHand), rr = of_role(samples, Role::RightHand);
  size_t both = 0;
  for (size_t i = 0; i < l.size(); ++i) both += !l[i].valid && !rr[i].valid;
  EXPECT_NEAR(static_cast<double>(both) / static_cast<double>(l.size()), expected * expected, 0.3 * expected * expected);
}

TEST(TrackerSim, RejectsBadOptionsAndClips) {
  SimOptions opt;
  opt.rate_hz = 0;
  EXPECT_THROW((void)simulate_trackers(walk(), opt), SimError);
  opt = {};
  opt.position_noise_mm = -1;
  EXPECT_NE(opt.validate().find("position_noise_mm"), std::string::npos);
  opt = {};
  opt.jitter_ms = NAN;
  EXPECT_THROW((void)simulate_trackers(walk(), opt), SimError);
  opt = {};
  opt.role_rate_hz[1] = -5;
  EXPECT_THROW((void)simulate_trackers(walk(), opt), SimError);

  Motion no_frames = walk();
  no_frames.frames.clear();
  EXPECT_THROW((void)simulate_trackers(no_frames, SimOptions{}), SimError);
  Motion no_head = walk();
  no_head.skeleton.names[static_cast<size_t>(no_head.skeleton.find("Head"))] = "Kopf";
  try {
    (void)simulate_trackers(no_head, SimOptions{});
    FAIL();
  } catch (const SimError& e) {
    EXPECT_NE(std::string(e.what()).find("'Head'"), std::string::npos) << e.what();
  }
  Motion broken = walk();
  broken.frames[3].local_rotations.pop_back();
  EXPECT_THROW((void)simulate_trackers(broken, SimOptions{}), SimError);

  // A one-frame clip gives one sample per role.
  Motion one = walk();
  one.frames.resize(1);
  EXPECT_EQ(simulate_trackers(one, SimOptions{}).size(), 3u);
}

// Issue 11: bodyd-sim wrote positions of 9e292 from a clip with a finite absurd value. The BVH
// reader now refuses such values; a clip whose joints still end up beyond the tracker range
// (offsets each within range, summed beyond it) is refused by the simulator with the joint
// and frame, and never becomes samples.
TEST(TrackerSim, RefusesJointsBeyondThePlausibleTrackerRange) {
  Motion far = walk();
  far.frames[7].local_translations[0].x() = 99.0;  // the root at 99 m: the head is beyond 100 m
  far.frames[7].local_translations[0].z() = 99.0;
  far.frames[7].local_translations[0].y() = 99.5;
  try {
    (void)simulate_trackers(far, SimOptions{});
    FAIL() << "no error";
  } catch (const SimError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("joint 'Head' is at ("), std::string::npos) << msg;
    EXPECT_NE(msg.find("in frame 7, outside the plausible range +-100 m"), std::string::npos) << msg;
  }
  Motion huge = walk();
  huge.frames[2].local_translations[0].y() = 1e300;  // what the old reader let through
  EXPECT_THROW((void)simulate_trackers(huge, SimOptions{}), SimError);
}

// Real clips: the no-noise error against independent FK, reported and bounded.
TEST(TrackerSim, NoNoiseMatchesFkOnRealClips) {
  if (!test::have_bandai()) GTEST_SKIP() << "no " << test::bandai();
  std::ifstream list(test::bandai() / "splits" / "val.txt");
  std::string name;
  int clips = 0;
  double worst_mm = 0;
  while (std::getline(list, name) && clips < 5) {
    if (name.empty()) continue;
    const Motion m = read_bvh(test::bandai() / name);
    // Three samples per frame (every frame time sampled), then exactly 90 Hz: the BVH
    // frame time 0.0333333 s is not 1/30 s, so 90 Hz samples fall between frames.
    const MaxError e3 = max_error(m, 3.0 * m.fps());
    const MaxError e90 = max_error(m, 90.0);
    std::cout << name << " (" << m.frame_count() << " frames): at frame times max " << e3.at_frames_mm << " mm, "
              << e3.at_frames_deg << " deg (" << e3.at_frames << " samples); 90 Hz vs interpolated FK max "
              << std::max(e90.at_frames_mm, e90.between_mm) << " mm\n";
    EXPECT_EQ(e3.at_frames, 3 * m.frame_count()) << name;
    EXPECT_LT(e3.at_frames_mm, 1.0) << name;
    EXPECT_LT(std::max(e90.at_frames_mm, e90.between_mm), 1.0) << name;
    worst_mm = std::max(worst_mm, e3.at_frames_mm);
    ++clips;
  }
  EXPECT_EQ(clips, 5);
  RecordProperty("worst_mm", std::to_string(worst_mm));
}
