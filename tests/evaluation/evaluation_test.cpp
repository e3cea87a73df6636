#include "bodyd/inference/evaluation.h"

#include "bodyd/inference/factory.h"
#include "bodyd/inference/ik.h"
#include "bodyd/inference/tracker_history.h"
#include "bodyd/motion/split_file.h"
#include "bodyd/simulators/tracker_sim.h"

#include "../test_paths.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>

using namespace bodyd;

namespace {

const std::filesystem::path kWalk = test::fixtures() / "walk_60.bvh";
const std::filesystem::path kBow = test::fixtures() / "bow_30.bvh";

TrackerSource simulator(double noise_mm, double dropout_rate_hz, std::uint64_t seed) {
  return [=](const Motion& clip, int index) {
    SimOptions o;
    o.rate_hz = clip.fps();
    o.position_noise_mm = noise_mm;
    o.dropout_rate_hz = dropout_rate_hz;
    o.dropout_mean_ms = 200.0;
    o.seed = seed * 1000 + static_cast<std::uint64_t>(index);
    return simulate_trackers(clip, o);
  };
}

EvalReport evaluate_ik(std::vector<std::filesystem::path> clips, const TrackerSource& source,
                       std::optional<std::filesystem::path> out_dir = std::nullopt) {
  EvalOptions o;
  o.methods = {"ik"};
  o.out_dir = std::move(out_dir);
  return evaluate(clips, o, source);
}

// The report without its wall-clock timing (the only part that is not deterministic).
nlohmann::json without_timing(const EvalReport& r) {
  nlohmann::json j = nlohmann::json::parse(report_json(r));
  j.erase("timing");
  for (auto& [name, m] : j["methods"].items()) {
    m.erase("ms_per_frame_p50");
    m.erase("ms_per_frame_p99");
  }
  return j;
}

std::string run_command(const std::string& cmd, int& status) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (p == nullptr) {
    status = -1;
    return out;
  }
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), static_cast<int>(buf.size()), p) != nullptr) out += buf.data();
  status = pclose(p);
  return out;
}

struct EvalRun {
  int status = 0;
  std::string out;        // stdout and stderr
  nlohmann::json report;  // with run_eval_with_report, when it exits 0
};

// bodyd-eval with `args`.
EvalRun run_eval(const std::string& args) {
  EvalRun run;
  run.out = run_command((test::bin_dir() / "bodyd-eval").string() + " " + args, run.status);
  return run;
}

// bodyd-eval with `args` and --json to a file in a temporary directory, and the report it wrote.
EvalRun run_eval_with_report(const std::string& args) {
  const test::TempDir dir("bodyd-eval-report");
  const std::filesystem::path json = dir.path / "report.json";
  EvalRun run = run_eval("--json " + json.string() + " " + args);
  if (run.status == 0) {
    std::ifstream in(json);
    run.report = nlohmann::json::parse(in);
  }
  return run;
}

// A reconstructor that breaks the contract: it reports the newest head sample pushed, even one
// later than the requested time. check_causality must catch it.
class PeekingReconstructor final : public Reconstructor {
 public:
  explicit PeekingReconstructor(const Skeleton& s) : skeleton_(s) {}
  std::string_view name() const override { return "peeking"; }
  const Skeleton& skeleton() const override { return skeleton_; }
  void push(const TrackerSample& s) override { history_.push(s); }
  bool reconstruct(std::int64_t t_ns, BodyPose& out) override {
    const TrackerSample* head = history_.newest(Role::Head);
    if (head == nullptr) return false;
    out.t_ns = t_ns;
    out.pose = rest_pose(skeleton_);
    out.pose.local_translations[1] = head->position_m;
    out.global = forward_kinematics(skeleton_, out.pose);
    return true;
  }
  void reset() override { history_.clear(); }
  void set_head_height_m(double) override {}
  double head_height_m() const override { return 1.0; }

 private:
  Skeleton skeleton_;
  TrackerHistory history_;
};

// The clip's trackers simulated at its frame rate, with the simulator's other defaults.
std::vector<TrackerSample> trackers_at_clip_rate(const Motion& clip) {
  SimOptions o;
  o.rate_hz = clip.fps();
  return simulate_trackers(clip, o);
}

}  // namespace

TEST(Evaluation, FrameTimesMatchTheSimulatorsSampleTimes) {
  const Motion clip = read_bvh(kWalk);
  const std::vector<TrackerSample> samples = trackers_at_clip_rate(clip);
  const std::vector<std::int64_t> times = clip_frame_times_ns(clip);
  ASSERT_EQ(times.size(), 60u);
  ASSERT_EQ(samples.size(), 3u * times.size());
  for (size_t k = 0; k < times.size(); ++k)
    for (size_t r = 0; r < 3; ++r) EXPECT_EQ(samples[3 * k + r].t_ns, times[k]) << "frame " << k;
}

TEST(Evaluation, IkOnWalkWithoutNoise) {
  const EvalReport r = evaluate_ik({kWalk}, simulator(0.0, 0.0, 1));
  EXPECT_EQ(r.clips, 1);
  EXPECT_EQ(r.frames, 60);
  ASSERT_EQ(r.methods.size(), 1u);
  const AccuracyMetrics& m = r.methods[0].metrics;
  for (const MetricKey& k : kMetricKeys) EXPECT_TRUE(std::isfinite(m.*k.field)) << k.key;
  EXPECT_LT(m.hand_pe_cm, 0.5);  // IK puts the hands on the trackers (up to the arm's reach)
  EXPECT_GT(m.mpjpe_cm, 1.0);    // but it is not the ground truth
  EXPECT_LT(m.mpjpe_cm, 20.0);
  EXPECT_EQ(r.methods[0].unanswered_frames, 0);
  EXPECT_EQ(r.timing_method, "ik");

  // Ground truth's jitter and skating, computed here directly from the definitions.
  const Motion clip = read_bvh(kWalk);
  std::vector<GlobalPose> g;
  for (const Pose& p : clip.frames) g.push_back(forward_kinematics(clip.skeleton, p));
  double jitter = 0.0;
  int jn = 0;
  for (size_t f = 3; f < g.size(); ++f)
    for (int j = 1; j < clip.skeleton.size(); ++j) {
      const auto jj = static_cast<size_t>(j);
      jitter += (g[f].positions[jj] - 3.0 * g[f - 1].positions[jj] + 3.0 * g[f - 2].positions[jj] -
                 g[f - 3].positions[jj])
                    .norm() *
                std::pow(clip.fps(), 3);
      ++jn;
    }
  int skating = 0, pairs = 0;
  for (const char* toes : {"Toes_L", "Toes_R"}) {
    const auto j = static_cast<size_t>(clip.skeleton.find(toes));
    for (size_t f = 1; f < g.size(); ++f) {
      const Vec3 a = g[f - 1].positions[j], b = g[f].positions[j];
      const double speed =
          std::sqrt((b.x() - a.x()) * (b.x() - a.x()) + (b.z() - a.z()) * (b.z() - a.z())) * clip.fps();
      skating += a.y() < 0.06 && b.y() < 0.06 && speed > 0.075;
      ++pairs;
    }
  }
  EXPECT_NEAR(r.ground_truth.jitter_m_s3, jitter / jn, 1e-6 * jitter / jn);
  EXPECT_NEAR(r.ground_truth.foot_skate_ratio, static_cast<double>(skating) / pairs, 1e-12);
  EXPECT_GT(r.ground_truth.jitter_m_s3, 0.0);
}

TEST(Evaluation, CausalityHelperPassesIkAndCatchesAPeekingReconstructor) {
  const Motion clip = read_bvh(kWalk);
  const std::vector<TrackerSample> samples = trackers_at_clip_rate(clip);
  const std::vector<std::int64_t> times = clip_frame_times_ns(clip);
  const std::int64_t t_star = times[29];

  const CausalityReport ik = check_causality(
      [&] { return make_reconstructor("ik", {}, &clip.skeleton); }, samples, times, t_star);
  EXPECT_TRUE(ik.causal) << ik.message;
  EXPECT_EQ(ik.frames_checked, 30);
  EXPECT_TRUE(ik.future_changed);  // the perturbation reached the outputs after t*

  const CausalityReport peek = check_causality(
      [&] { return std::make_unique<PeekingReconstructor>(clip.skeleton); }, samples, times, t_star);
  EXPECT_FALSE(peek.causal);
  EXPECT_GE(peek.first_violation, 0);
  EXPECT_LE(peek.first_violation, 29);
  EXPECT_NE(peek.message.find("peeking"), std::string::npos) << peek.message;
}

TEST(Evaluation, DeterministicForASeedAndTheSeedMatters) {
  const auto run = [&](std::uint64_t seed) {
    return without_timing(evaluate_ik({kWalk, kBow}, simulator(5.0, 1.0, seed)));
  };
  const nlohmann::json a = run(3), b = run(3), c = run(4);
  EXPECT_EQ(a.dump(), b.dump());
  EXPECT_NE(a["methods"]["ik"]["mpjpe_cm"], c["methods"]["ik"]["mpjpe_cm"]);
  EXPECT_EQ(a["clips"], 2);
  EXPECT_EQ(a["frames"], 90);
}

TEST(Evaluation, JsonHasExactlyTheDocumentedKeys) {
  const nlohmann::ordered_json j =
      nlohmann::ordered_json::parse(report_json(evaluate_ik({kBow}, simulator(0.0, 0.0, 1))));
  std::vector<std::string> top;
  for (auto& [k, v] : j.items()) top.push_back(k);
  EXPECT_EQ(top, (std::vector<std::string>{"trackers", "clips", "frames", "methods", "ground_truth", "timing",
                                           "groups", "body_scale", "calibration"}));
  for (const MetricKey& k : kExtraMetricKeys) EXPECT_TRUE(j["methods"]["ik"].contains(std::string(k.key))) << k.key;
  EXPECT_TRUE(j["groups"]["dataset"].contains("other"));
  for (const MetricKey& k : kMetricKeys) EXPECT_TRUE(j["methods"]["ik"][std::string(k.key)].is_number()) << k.key;
  EXPECT_EQ(j["ground_truth"].size(), 4u);
  EXPECT_TRUE(j["ground_truth"]["jitter_m_s3"].is_number());
  EXPECT_TRUE(j["ground_truth"]["foot_skate_ratio"].is_number());
  // jitter_by_joint_m_s3: the 21 body joints by name, in the method and in the truth.
  for (const auto* o : {&j["methods"]["ik"], &j["ground_truth"]}) {
    const auto& by_joint = (*o)["jitter_by_joint_m_s3"];
    ASSERT_TRUE(by_joint.is_object());
    EXPECT_EQ(by_joint.size(), 21u);
    EXPECT_EQ(by_joint.begin().key(), "Spine");
    EXPECT_TRUE(by_joint["Toes_R"].is_number());
  }
  // pe_by_joint_cm and height_error_by_joint_cm: the method's only.
  for (const char* key : {"pe_by_joint_cm", "height_error_by_joint_cm"}) {
    const auto& by_joint = j["methods"]["ik"][key];
    ASSERT_TRUE(by_joint.is_object()) << key;
    EXPECT_EQ(by_joint.size(), 21u) << key;
    EXPECT_EQ(by_joint.begin().key(), "Spine") << key;
    EXPECT_TRUE(by_joint["Toes_R"].is_number()) << key;
    EXPECT_FALSE(j["ground_truth"].contains(key)) << key;
  }
  EXPECT_EQ(j["timing"].size(), 2u);
  EXPECT_TRUE(j["timing"]["ms_per_frame_p50"].is_number());
  EXPECT_TRUE(j["timing"]["ms_per_frame_p99"].is_number());
}

TEST(Evaluation, OutDirHoldsReadableReconstructions) {
  const auto dir = std::filesystem::temp_directory_path() / "bodyd_eval_test_out";
  std::filesystem::remove_all(dir);
  (void)evaluate_ik({kWalk}, simulator(0.0, 0.0, 1), dir);
  const Motion truth = read_bvh(kWalk);
  const Motion pred = read_bvh(dir / "walk_60.ik.pred.bvh");
  EXPECT_EQ(pred.frame_count(), truth.frame_count());
  EXPECT_EQ(pred.skeleton.names, truth.skeleton.names);
  EXPECT_EQ(pred.channels, truth.channels);
  EXPECT_NEAR(pred.frame_time_s, truth.frame_time_s, 1e-9);
  // The written hands are on the tracked (true) hands, to the file's precision.
  const auto hand = static_cast<size_t>(truth.skeleton.find("Hand_R"));
  double err = 0.0;
  for (int f = 0; f < truth.frame_count(); ++f)
    err += (forward_kinematics(pred.skeleton, pred.frames[static_cast<size_t>(f)]).positions[hand] -
            forward_kinematics(truth.skeleton, truth.frames[static_cast<size_t>(f)]).positions[hand])
               .norm();
  EXPECT_LT(err / truth.frame_count(), 0.01);
  std::filesystem::remove_all(dir);
}

TEST(Evaluation, SplitFilesResolveAgainstTheDatasetRoot) {
  const auto root = std::filesystem::temp_directory_path() / "bodyd_eval_split_test";
  std::filesystem::remove_all(root);
  std::filesystem::create_directories(root / "splits");
  std::filesystem::create_directories(root / "clips");
  std::filesystem::copy_file(kBow, root / "clips" / "bow.bvh");
  {
    std::ofstream(root / "splits" / "val.txt") << "# comment\n\nclips/bow.bvh\n";
    std::ofstream(root / "splits" / "bad.txt") << "clips/bow.bvh\nclips/missing.bvh\n";
  }
  const auto paths = read_split(root / "splits" / "val.txt");
  ASSERT_EQ(paths.size(), 1u);
  EXPECT_TRUE(std::filesystem::exists(paths[0]));
  try {
    (void)read_split(root / "splits" / "bad.txt");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.txt:2"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)read_split(root / "splits" / "none.txt"), std::runtime_error);
  std::filesystem::remove_all(root);
}

TEST(BodydEval, CommandLineWritesTheReportAndExplainsMissingMethods) {
  const EvalRun ik = run_eval_with_report("--methods ik --seed 2 --noise-mm 3 " + kWalk.string() + " " + kBow.string());
  ASSERT_EQ(ik.status, 0) << ik.out;
  EXPECT_NE(ik.out.find("mpjpe_cm"), std::string::npos) << ik.out;
  EXPECT_EQ(ik.report["clips"], 2);
  EXPECT_EQ(ik.report["frames"], 90);
  EXPECT_TRUE(ik.report["methods"]["ik"]["mpjpe_cm"].is_number());

  const EvalRun no_model = run_eval_with_report("--methods diffusion,ik " + kBow.string());
  EXPECT_NE(no_model.status, 0);
  EXPECT_NE(no_model.out.find("diffusion"), std::string::npos) << no_model.out;
  const EvalRun no_clip = run_eval("--methods ik " + (test::fixtures() / "no_such.bvh").string());
  EXPECT_NE(no_clip.status, 0);
  EXPECT_NE(no_clip.out.find("no_such.bvh"), std::string::npos) << no_clip.out;
}

// Issue 11: a clip with one finite absurd value (1e300) made bodyd-eval print nan/inf metrics
// and exit 0. Now the clip is refused with its file and line, and no metric is printed.
TEST(BodydEval, AbsurdClipIsAnErrorNotNanMetrics) {
  std::ifstream in(kWalk, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  size_t pos = 0;
  for (int line = 1; line < 140; ++line) pos = text.find('\n', pos) + 1;
  text.replace(pos, text.find(' ', pos) - pos, "1e300");  // frame 5's root Xposition
  const auto bad = std::filesystem::temp_directory_path() / "bodyd_eval_absurd_test.bvh";
  std::ofstream(bad, std::ios::binary) << text;
  const EvalRun run = run_eval("--methods ik " + bad.string());
  std::filesystem::remove(bad);
  EXPECT_NE(run.status, 0) << run.out;
  EXPECT_NE(run.out.find(bad.string() + ":140:"), std::string::npos) << run.out;
  EXPECT_EQ(run.out.find(" nan"), std::string::npos) << run.out;
  EXPECT_EQ(run.out.find(" inf"), std::string::npos) << run.out;
  EXPECT_EQ(run.out.find("mpjpe_cm"), std::string::npos) << run.out;
}

// Groups come from dataset-N_{content}_{style}_{take}.bvh names: copies of the fixtures under such
// names give known counts, and a group's metrics are those of its clips alone.
TEST(Evaluation, GroupsFromDatasetFileNamesHaveTheirClipsAndFrames) {
  const auto dir = std::filesystem::temp_directory_path() / "bodyd_eval_groups_test";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto walk_a = dir / "dataset-2_walk_normal_002.bvh", walk_b = dir / "dataset-2_walk_normal_003.bvh";
  const auto bow = dir / "dataset-1_bow_active_001.bvh";
  std::filesystem::copy_file(kWalk, walk_a);
  std::filesystem::copy_file(kWalk, walk_b);
  std::filesystem::copy_file(kBow, bow);
  const nlohmann::json j = without_timing(evaluate_ik({walk_a, bow, walk_b}, simulator(0.0, 0.0, 1)));
  const nlohmann::json& g = j["groups"];
  const auto expect_group = [&](const char* category, const char* name, int clips, int frames) {
    SCOPED_TRACE(std::string(category) + " " + name);
    ASSERT_TRUE(g[category].contains(name)) << g[category].dump();
    EXPECT_EQ(g[category][name]["clips"], clips);
    EXPECT_EQ(g[category][name]["frames"], frames);
  };
  expect_group("dataset", "dataset-2", 2, 120);
  expect_group("dataset", "dataset-1", 1, 30);
  expect_group("content", "walk", 2, 120);
  expect_group("content", "bow", 1, 30);
  expect_group("style", "normal", 2, 120);
  expect_group("style", "active", 1, 30);
  for (const char* category : {"dataset", "content", "style"}) EXPECT_EQ(g[category].size(), 2u) << category;
  // The bow's groups hold exactly the bow clip evaluated alone.
  const nlohmann::json alone = without_timing(evaluate_ik({kBow}, simulator(0.0, 0.0, 1)));
  EXPECT_DOUBLE_EQ(g["content"]["bow"]["methods"]["ik"]["mpjpe_cm"].get<double>(),
                   alone["methods"]["ik"]["mpjpe_cm"].get<double>());
  EXPECT_DOUBLE_EQ(g["style"]["active"]["methods"]["ik"]["lower_pe_cm"].get<double>(),
                   alone["methods"]["ik"]["lower_pe_cm"].get<double>());
  std::filesystem::remove_all(dir);
}

// --body-scale: the bow starts standing, so the detector calibrates from its first still half
// second; the walk never stands still, so the fallback does. Both land within 2% of the scaled
// skeleton's standing head height, and the report is the same on a second run.
TEST(Evaluation, BodyScaleCalibratesNearTheTrueScaleAndIsDeterministic) {
  const auto run = [&](double scale) {
    EvalOptions o;
    o.methods = {"diffusion"};
    o.model_path = test::fixtures() / "tiny_model.safetensors";
    o.body_scale = scale;
    o.calibrate = true;
    return evaluate(std::vector<std::filesystem::path>{kBow, kWalk}, o, simulator(2.0, 0.0, 7));
  };
  for (double scale : {0.8, 1.2}) {
    SCOPED_TRACE(scale);
    const EvalReport r = run(scale);
    EXPECT_EQ(r.calibrated_clips, 2);
    EXPECT_EQ(r.fallback_clips, 1);
    EXPECT_LT(r.calibration_scale_error_max, 0.02);
    EXPECT_GE(r.calibration_scale_error, 0.0);
    // The head height error: at most 2% of a standing head height (under 1.5 m x scale).
    EXPECT_LT(r.calibration_error_cm, 100.0 * 0.02 * 1.5 * scale);
    EXPECT_GT(r.calibration_error_cm, 0.0);
    EXPECT_GT(r.calibration_time_s, 0.4);
    const nlohmann::json a = without_timing(r), b = without_timing(run(scale));
    EXPECT_EQ(a.dump(), b.dump());
    EXPECT_EQ(a["body_scale"], scale);
    EXPECT_EQ(a["calibration"]["clips_fallback"], 1);
  }
}

TEST(BodydEval, BodyScaleFlagCalibrates) {
  const std::string diffusion = "--methods diffusion --model " + (test::fixtures() / "tiny_model.safetensors").string();
  const EvalRun scaled = run_eval_with_report(diffusion + " --body-scale 1.2 " + kBow.string());
  ASSERT_EQ(scaled.status, 0) << scaled.out;
  EXPECT_NE(scaled.out.find("body scale 1.2: calibrated on 1 of 1 clips (0 by the fallback)"), std::string::npos)
      << scaled.out;
  const nlohmann::json& j = scaled.report;
  EXPECT_EQ(j["body_scale"], 1.2);
  EXPECT_EQ(j["calibration"]["enabled"], true);
  EXPECT_EQ(j["calibration"]["clips_calibrated"], 1);
  EXPECT_LT(j["calibration"]["scale_error"].get<double>(), 0.02);

  // The tracker filter's flags: a bad value is refused, naming it.
  const EvalRun bad = run_eval(diffusion + " --filter-min-cutoff-hz 0 " + kBow.string());
  EXPECT_NE(bad.status, 0) << bad.out;
  EXPECT_NE(bad.out.find("min_cutoff_hz must be > 0"), std::string::npos) << bad.out;
}
