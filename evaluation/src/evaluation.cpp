#include "bodyd/inference/evaluation.h"

#include "bodyd/base/percentile.h"
#include "bodyd/base/require.h"
#include "bodyd/base/user_error.h"
#include "bodyd/inference/body_pipeline.h"
#include "bodyd/inference/factory.h"
#include "bodyd/inference/ik.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <stdexcept>

namespace bodyd {

std::vector<std::int64_t> clip_frame_times_ns(const Motion& clip) {
  const double period_ns = 1e9 / clip.fps();
  std::vector<std::int64_t> times(static_cast<size_t>(clip.frame_count()));
  for (size_t k = 0; k < times.size(); ++k) times[k] = std::llround(static_cast<double>(k) * period_ns);
  return times;
}

OnlineRun run_online(Reconstructor& reconstructor, std::span<const TrackerSample> samples,
                     std::span<const std::int64_t> frame_times_ns, std::int64_t lookahead_ns) {
  OnlineRun run;
  const size_t n = frame_times_ns.size();
  run.poses.resize(n);
  run.answered.assign(n, false);
  run.ms_per_frame.resize(n);
  size_t next = 0;
  int first_answer = -1;
  BodyPose pose;
  for (size_t f = 0; f < n; ++f) {
    const std::int64_t t = frame_times_ns[f];
    while (next < samples.size() && samples[next].t_ns <= t + lookahead_ns) reconstructor.push(samples[next++]);
    const auto start = std::chrono::steady_clock::now();
    const bool ok = reconstructor.reconstruct(t, pose);
    const auto stop = std::chrono::steady_clock::now();
    run.ms_per_frame[f] = std::chrono::duration<double, std::milli>(stop - start).count();
    run.answered[f] = ok;
    if (ok) {
      run.poses[f] = pose;
      if (first_answer < 0) first_answer = static_cast<int>(f);
    } else {
      ++run.unanswered;
      if (f > 0) run.poses[f] = run.poses[f - 1];
    }
  }
  if (first_answer > 0)
    for (int f = 0; f < first_answer; ++f) run.poses[static_cast<size_t>(f)] = run.poses[static_cast<size_t>(first_answer)];
  return run;
}

namespace {

bool same_pose(const BodyPose& a, const BodyPose& b, std::string& what) {
  if (a.pose.local_rotations.size() != b.pose.local_rotations.size()) {
    what = "joint count";
    return false;
  }
  for (size_t j = 0; j < a.pose.local_rotations.size(); ++j) {
    if (a.pose.local_rotations[j].coeffs() != b.pose.local_rotations[j].coeffs()) {
      what = fmt::format("local rotation of joint {}", j);
      return false;
    }
    if (a.pose.local_translations[j] != b.pose.local_translations[j]) {
      what = fmt::format("local translation of joint {}", j);
      return false;
    }
  }
  if (a.foot_contact != b.foot_contact) {
    what = "foot contacts";
    return false;
  }
  if (a.tracker_valid != b.tracker_valid) {
    what = "tracker validity";
    return false;
  }
  return true;
}

}  // namespace

CausalityReport check_causality(const std::function<std::unique_ptr<Reconstructor>()>& make,
                                std::span<const TrackerSample> samples,
                                std::span<const std::int64_t> frame_times_ns, std::int64_t t_star_ns,
                                std::int64_t lookahead_ns) {
  std::vector<TrackerSample> changed(samples.begin(), samples.end());
  const Quat turn(Eigen::AngleAxisd(M_PI / 3.0, Vec3(1.0, 2.0, 3.0).normalized()));
  int k = 0;
  for (TrackerSample& s : changed) {
    if (s.t_ns <= t_star_ns) continue;
    s.position_m += Vec3(0.3, -0.2, 0.25);
    s.rotation = (turn * s.rotation).normalized();
    if (++k % 3 == 0) s.valid = !s.valid;
  }
  const auto original = make();
  const auto perturbed = make();
  const OnlineRun a = run_online(*original, samples, frame_times_ns, lookahead_ns);
  const OnlineRun b = run_online(*perturbed, changed, frame_times_ns, lookahead_ns);

  CausalityReport report;
  for (size_t f = 0; f < frame_times_ns.size(); ++f) {
    std::string what;
    const bool same = a.answered[f] == b.answered[f] && same_pose(a.poses[f], b.poses[f], what);
    if (a.answered[f] != b.answered[f]) what = "whether a pose was produced";
    if (frame_times_ns[f] <= t_star_ns) {
      ++report.frames_checked;
      if (!same && report.causal) {
        report.causal = false;
        report.first_violation = static_cast<int>(f);
        report.message = fmt::format(
            "{}: frame {} (t = {} ns <= t* = {} ns) changed ({}) when only samples after t* changed",
            original->name(), f, frame_times_ns[f], t_star_ns, what);
      }
    } else if (!same) {
      report.future_changed = true;
    }
  }
  return report;
}

namespace {

// Where each joint of `truth` (by name) is in `predicted`; empty when the orders agree.
std::vector<int> joint_map(const Skeleton& truth, const Skeleton& predicted, const std::string& method) {
  if (truth.names == predicted.names) return {};
  std::vector<int> map(truth.names.size());
  for (size_t j = 0; j < truth.names.size(); ++j) {
    map[j] = predicted.find(truth.names[j]);
    if (map[j] < 0)
      throw UserError(fmt::format("method '{}'", method),
                      fmt::format("its skeleton has no joint '{}' of the clip's skeleton", truth.names[j]),
                      "evaluate clips on the model's skeleton (the bundled motion data's)");
  }
  return map;
}

// Remaps a pose into the clip's joint order (no-op for an empty map).
void remap(const std::vector<int>& map, const BodyPose& in, Pose& pose, GlobalPose& global) {
  if (map.empty()) {
    pose = in.pose;
    global = in.global;
    return;
  }
  pose.local_rotations.resize(map.size());
  pose.local_translations.resize(map.size());
  global.positions.resize(map.size());
  global.rotations.resize(map.size());
  for (size_t j = 0; j < map.size(); ++j) {
    const auto s = static_cast<size_t>(map[j]);
    pose.local_rotations[j] = in.pose.local_rotations[s];
    pose.local_translations[j] = in.pose.local_translations[s];
    global.positions[j] = in.global.positions[s];
    global.rotations[j] = in.global.rotations[s];
  }
}

// A reconstructor behind the daemon's body pipeline (bodyd/inference/body_pipeline.h): every
// sample goes through the daemon's conditioning and calibrations on its way in, a sample's time
// standing for its arrival. What the calibrations applied is kept for the report.
class ThroughPipeline final : public Reconstructor {
 public:
  explicit ThroughPipeline(std::unique_ptr<Reconstructor> inner) : inner_(std::move(inner)) {}
  // Set up before the first sample (the mounting, the calibrations the options ask for).
  BodyPipeline& pipeline() { return pipeline_; }
  std::string_view name() const override { return inner_->name(); }
  const Skeleton& skeleton() const override { return inner_->skeleton(); }
  void push(const TrackerSample& s) override {
    const SampleEvents events = pipeline_.push(s, s.t_ns, *inner_);
    if (events.raw.calibration_pose) pose_found_ = events.raw.calibration_pose->calibration;
    if (events.height && events.height->outcome == AutoHeightEvent::Outcome::Applied) height_found_ = events.height->height;
  }
  bool reconstruct(std::int64_t t_ns, BodyPose& out) override { return inner_->reconstruct(t_ns, out); }
  void reset() override {
    inner_->reset();
    pipeline_.time_restarted();
  }
  // Forwarded (issue 45: a decorator once forgot it, so the report's refused count read 0).
  std::int64_t refused_samples() const override { return inner_->refused_samples(); }
  void set_head_height_m(double h) override { inner_->set_head_height_m(h); }
  double head_height_m() const override { return inner_->head_height_m(); }
  // The calibration pose found (its height applied or not), and the auto height calibration's
  // standing height applied, if any.
  const std::optional<PoseCalibration>& pose_found() const { return pose_found_; }
  const std::optional<StandingHeight>& height_found() const { return height_found_; }

 private:
  std::unique_ptr<Reconstructor> inner_;
  BodyPipeline pipeline_;
  std::optional<PoseCalibration> pose_found_;
  std::optional<StandingHeight> height_found_;
};

EvalReport::MountingError mounting_error(const Mounting& est, const Mounting& truth,
                                         const std::array<bool, kRoleCount>& body_roles,
                                         const std::array<bool, kRoleCount>& rotation_only) {
  EvalReport::MountingError e;
  // Body trackers: the mean over `body_roles` (those tracked, or those measured). A rotation-only
  // tracker's offset is not used, so not scored.
  double n = 0.0, n_offset = 0.0;
  for (Role r : kRoles) {
    const auto i = static_cast<size_t>(r);
    if (is_xr_role(r) || !body_roles[i]) continue;
    e.body_deg += geodesic_angle(est.T_device_joint[i].rotation, truth.T_device_joint[i].rotation) * 180.0 / M_PI;
    n += 1.0;
    if (rotation_only[i]) continue;
    e.body_offset_cm += 100.0 * (est.T_device_joint[i].position_m - truth.T_device_joint[i].position_m).norm();
    n_offset += 1.0;
  }
  e.body_n = n;  // sums here; divide_error makes them means over role-clips
  e.body_offset_n = n_offset;
  const RigidTransform& h = est.T_device_joint[0];
  const RigidTransform& ht = truth.T_device_joint[0];
  e.head_deg = geodesic_angle(h.rotation, ht.rotation) * 180.0 / M_PI;
  // Pitch: the part of the difference (in the device's axes) about the device's +X.
  const Vec3 d = axis_angle_from_quat((h.rotation * ht.rotation.conjugate()).normalized());
  e.head_pitch_deg = std::abs(d.x()) * 180.0 / M_PI;
  e.eye_offset_cm = 100.0 * (h.position_m - ht.position_m).norm();
  for (int r = 1; r <= 2; ++r) {
    e.grip_deg += 0.5 * geodesic_angle(est.T_device_joint[static_cast<size_t>(r)].rotation,
                                       truth.T_device_joint[static_cast<size_t>(r)].rotation) * 180.0 / M_PI;
    e.grip_offset_cm += 0.5 * 100.0 * (est.T_device_joint[static_cast<size_t>(r)].position_m -
                                       truth.T_device_joint[static_cast<size_t>(r)].position_m).norm();
  }
  return e;
}

void add_error(EvalReport::MountingError& sum, const EvalReport::MountingError& e) {
  sum.head_deg += e.head_deg;
  sum.head_pitch_deg += e.head_pitch_deg;
  sum.grip_deg += e.grip_deg;
  sum.eye_offset_cm += e.eye_offset_cm;
  sum.grip_offset_cm += e.grip_offset_cm;
  sum.body_deg += e.body_deg;
  sum.body_offset_cm += e.body_offset_cm;
  sum.body_n += e.body_n;
  sum.body_offset_n += e.body_offset_n;
}

void divide_error(EvalReport::MountingError& e, double n) {
  const double k = n > 0 ? 1.0 / n : std::numeric_limits<double>::quiet_NaN();
  e.head_deg *= k;
  e.head_pitch_deg *= k;
  e.grip_deg *= k;
  e.eye_offset_cm *= k;
  e.grip_offset_cm *= k;
  e.body_deg = e.body_n > 0 ? e.body_deg / e.body_n : std::numeric_limits<double>::quiet_NaN();
  e.body_offset_cm = e.body_offset_n > 0 ? e.body_offset_cm / e.body_offset_n : std::numeric_limits<double>::quiet_NaN();
}

// Whether each hand's tracker is valid at each frame time (the newest sample at or before it).
std::vector<std::array<bool, 2>> hand_validity(std::span<const TrackerSample> samples,
                                               std::span<const std::int64_t> frame_times_ns) {
  std::vector<std::array<bool, 2>> valid(frame_times_ns.size(), {false, false});
  std::array<bool, 2> now{false, false};
  size_t next = 0;
  for (size_t f = 0; f < frame_times_ns.size(); ++f) {
    for (; next < samples.size() && samples[next].t_ns <= frame_times_ns[f]; ++next) {
      if (samples[next].role == Role::LeftHand) now[0] = samples[next].valid;
      if (samples[next].role == Role::RightHand) now[1] = samples[next].valid;
    }
    valid[f] = now;
  }
  return valid;
}

// Accumulators of one group: one per method.
struct GroupAcc {
  int clips = 0;
  std::int64_t frames = 0;
  std::vector<MetricsAccumulator> methods;
};

std::string out_name(const std::filesystem::path& clip, const std::string& method) {
  const std::string stem = clip.stem().string();
  return method == "diffusion" ? stem + ".pred.bvh" : stem + "." + method + ".pred.bvh";
}

}  // namespace

std::array<std::string, 3> clip_groups(const std::filesystem::path& clip) {
  // dataset-N_{content}_{style}_{take}: four '_'-separated parts, the first "dataset-...".
  const std::string stem = clip.stem().string();
  std::array<std::string, 4> parts;
  size_t start = 0, n = 0;
  for (; n < 4; ++n) {
    const size_t end = stem.find('_', start);
    parts[n] = stem.substr(start, end == std::string::npos ? std::string::npos : end - start);
    if (end == std::string::npos) {
      ++n;
      break;
    }
    start = end + 1;
  }
  const bool four = n == 4 && stem.find('_', start) == std::string::npos;  // no fifth part
  bool ok = four && parts[0].rfind("dataset-", 0) == 0;
  for (const std::string& p : parts) ok = ok && !p.empty();
  if (!ok) return {"other", "other", "other"};
  return {parts[0], parts[1], parts[2]};
}

Motion scale_motion(const Motion& clip, double s) {
  Motion out = clip;
  for (size_t j = 0; j < out.skeleton.offsets.size(); ++j) {
    out.skeleton.offsets[j] *= s;
    if (out.skeleton.end_sites[j]) *out.skeleton.end_sites[j] *= s;
  }
  for (Pose& p : out.frames)
    for (Vec3& t : p.local_translations) t *= s;
  return out;
}

EvalReport evaluate(std::span<const std::filesystem::path> clips, const EvalOptions& options,
                    const TrackerSource& source) {
  // The caller checks its flags (bodyd-eval: --methods, --body-scale's range): a bad one here is a bug.
  BODYD_REQUIRE(!options.methods.empty(), "evaluate: no methods given");
  BODYD_REQUIRE(options.body_scale > 0.0 && std::isfinite(options.body_scale), "evaluate: body scale must be > 0");
  if (options.out_dir) std::filesystem::create_directories(*options.out_dir);

  EvalReport report;
  report.body_scale = options.body_scale;
  report.calibrate = options.calibrate;
  std::optional<Skeleton> first_skeleton;
  std::vector<MetricsAccumulator> metrics;
  std::vector<std::vector<double>> times(options.methods.size());
  std::vector<std::int64_t> unanswered(options.methods.size(), 0);
  static constexpr std::array<const char*, 3> kCategories{"dataset", "content", "style"};
  std::array<std::map<std::string, GroupAcc>, 3> groups;
  double calibration_error_sum_cm = 0.0, scale_error_sum = 0.0, calibration_time_sum_s = 0.0;
  report.trackers = options.trackers;
  // The body trackers of the set (their mountings are scored with --device-frames xr).
  std::array<bool, kRoleCount> tracked_body{}, rotation_only{};
  {
    std::string set_error;
    if (const std::optional<TrackerSet> set = parse_tracker_set(options.trackers, set_error)) {
      for (Role r : set->roles) tracked_body[static_cast<size_t>(r)] = !is_xr_role(r);
      for (Role r : set->rotation_only) rotation_only[static_cast<size_t>(r)] = true;
    }
  }
  report.device_frames = options.device_frames;
  report.calibrate_pose = options.device_frames && options.calibrate_pose;
  const Mounting defaults = default_mounting(options.body_reference);
  double pose_time_sum_s = 0.0;

  // The model file is read and verified once, not once per clip (the sha256 and parsing were a
  // fifth of a validation run); every clip's reconstructor shares it.
  std::shared_ptr<const inference::Model> model;
  if (std::find(options.methods.begin(), options.methods.end(), "diffusion") != options.methods.end())
    model = load_reconstructor_model(options.model_path);

  int index = 0;
  for (const std::filesystem::path& path : clips) {
    const Motion clip = options.body_scale == 1.0 ? read_bvh(path) : scale_motion(read_bvh(path), options.body_scale);
    try {
      if (clip.frame_count() == 0) throw UserError("", "the clip has no frames", "leave it out of the clips or the split");
      if (!first_skeleton) {
        first_skeleton = clip.skeleton;
        for (size_t m = 0; m < options.methods.size(); ++m) metrics.emplace_back(clip.skeleton);
      } else if (clip.skeleton.names != first_skeleton->names) {
        throw UserError("", "its joints (names or order) differ from the first clip's",
                        "evaluate clips of one skeleton together");
      }
      const std::array<std::string, 3> names = clip_groups(path);
      std::array<GroupAcc*, 3> group{};
      for (size_t c = 0; c < 3; ++c) {
        GroupAcc& g = groups[c][names[c]];
        if (g.methods.empty())
          for (size_t m = 0; m < options.methods.size(); ++m) g.methods.emplace_back(clip.skeleton);
        ++g.clips;
        g.frames += clip.frame_count();
        group[c] = &g;
      }

      std::vector<GlobalPose> truth(static_cast<size_t>(clip.frame_count()));
      for (size_t f = 0; f < truth.size(); ++f) forward_kinematics(clip.skeleton, clip.frames[f], truth[f]);
      const std::vector<TrackerSample> samples = source(clip, index);
      const std::vector<std::int64_t> frame_times = clip_frame_times_ns(clip);
      const std::vector<std::array<bool, 2>> hands_valid = hand_validity(samples, frame_times);
      bool clip_calibrated = false;

      for (size_t m = 0; m < options.methods.size(); ++m) {
        const std::string& method = options.methods[m];
        auto reconstructor = std::make_unique<ThroughPipeline>(
            make_reconstructor_of(method, model, &clip.skeleton, options.reconstructor));
        // The calibrations of the options (EvalOptions): "ik" is given the clip's own skeleton,
        // so it is never calibrated.
        const bool calibrate_height = options.calibrate && method != "ik";
        BodyPipeline& pipeline = reconstructor->pipeline();
        if (options.device_frames) {
          const bool oracle = options.oracle_mounting && options.true_mounting;
          const Mounting start = oracle ? options.true_mounting(index) : defaults;
          pipeline.conditioner().set_default_mounting(start);
          if (oracle)
            for (Role r : kRoles) pipeline.conditioner().set_mounting(r, start.T_device_joint[static_cast<size_t>(r)]);
          if (options.calibrate_pose)
            pipeline.hold_calibration_pose(PoseCalibrator(options.body_reference, defaults, options.pose_calibration,
                                                          body_joints_in_pose(reconstructor->skeleton())),
                                           calibrate_height);
        } else if (calibrate_height) {
          pipeline.start_auto_height(options.calibration);
        }
        const OnlineRun run = run_online(*reconstructor, samples, frame_times);
        const std::optional<PoseCalibration>& pose_found = reconstructor->pose_found();
        if (options.device_frames && m == 0) {
          const Mounting truth = options.true_mounting ? options.true_mounting(index) : defaults;
          add_error(report.default_mounting_error, mounting_error(defaults, truth, tracked_body, rotation_only));
          if (pose_found) {
            ++report.pose_calibrated_clips;
            std::array<bool, kRoleCount> measured_body{};
            for (Role r : kRoles)
              measured_body[static_cast<size_t>(r)] = tracked_body[static_cast<size_t>(r)] && pose_found->measured[static_cast<size_t>(r)];
            add_error(report.calibrated_mounting_error,
                      mounting_error(pose_found->mounting, truth, measured_body, rotation_only));
            for (Role r : kRoles)
              if (tracked_body[static_cast<size_t>(r)] && !measured_body[static_cast<size_t>(r)]) ++report.body_trackers_unmeasured;
            pose_time_sum_s += static_cast<double>(pose_found->t_ns - samples.front().t_ns) * 1e-9;
            if (options.calibrate) {
              const PoseCalibration& c = *pose_found;
              const double truth_m = standing_head_height_m(clip.skeleton);
              ++report.calibrated_clips;
              calibration_error_sum_cm += 100.0 * std::abs(c.head_height_m - truth_m);
              scale_error_sum += std::abs(c.head_height_m / truth_m - 1.0);
              report.calibration_scale_error_max =
                  std::max(report.calibration_scale_error_max, std::abs(c.head_height_m / truth_m - 1.0));
              calibration_time_sum_s += static_cast<double>(c.t_ns - frame_times.front()) * 1e-9;
            }
          }
        }
        if (reconstructor->height_found() && !clip_calibrated) {
          clip_calibrated = true;
          const StandingHeight& h = *reconstructor->height_found();
          const double truth_m = standing_head_height_m(clip.skeleton);
          ++report.calibrated_clips;
          if (h.fallback) ++report.fallback_clips;
          calibration_error_sum_cm += 100.0 * std::abs(h.head_height_m - truth_m);
          scale_error_sum += std::abs(h.head_height_m / truth_m - 1.0);
          report.calibration_scale_error_max = std::max(report.calibration_scale_error_max, std::abs(h.head_height_m / truth_m - 1.0));
          calibration_time_sum_s += static_cast<double>(h.t_ns - frame_times.front()) * 1e-9;
        }
        if (run.unanswered == clip.frame_count())
          throw UserError(fmt::format("method '{}'", method), "produced no pose for any frame",
                          "check the clip's trackers: the head must be tracked (no valid head sample?)");
        unanswered[m] += run.unanswered;
        times[m].insert(times[m].end(), run.ms_per_frame.begin(), run.ms_per_frame.end());

        const std::vector<int> map = joint_map(clip.skeleton, reconstructor->skeleton(), method);
        Motion written;
        if (options.out_dir) {
          written.skeleton = clip.skeleton;
          written.channels = clip.channels;
          written.frame_time_s = clip.frame_time_s;
          written.frames.resize(truth.size());
        }
        Pose pose;
        GlobalPose global;
        metrics[m].begin_clip(clip.fps());
        for (GroupAcc* g : group) g->methods[m].begin_clip(clip.fps());
        for (size_t f = 0; f < truth.size(); ++f) {
          remap(map, run.poses[f], pose, global);
          metrics[m].add_frame(global, truth[f], hands_valid[f]);
          for (GroupAcc* g : group) g->methods[m].add_frame(global, truth[f], hands_valid[f]);
          if (options.out_dir) written.frames[f] = pose;
        }
        (void)metrics[m].end_clip();
        for (GroupAcc* g : group) (void)g->methods[m].end_clip();
        if (options.out_dir) write_bvh(*options.out_dir / out_name(path, method), written);
      }
    } catch (const ReconstructorError&) {
      throw;  // says which method and what to do; the same for every clip
    } catch (const UserError& e) {
      throw UserError(e.problem().under(path.string()));
    } catch (const std::exception& e) {  // a file system error of --out-dir, a tracker source's failure
      throw UserError(path.string(), e.what());
    }
    ++report.clips;
    report.frames += clip.frame_count();
    if (options.on_clip) options.on_clip(index, static_cast<int>(clips.size()), path);
    ++index;
  }

  size_t timed = 0;
  for (size_t m = 0; m < options.methods.size(); ++m) {
    MethodReport r;
    r.name = options.methods[m];
    if (!metrics.empty()) {
      r.metrics = metrics[m].result();
      r.jitter_by_joint_m_s3 = metrics[m].jitter_by_joint();
      r.pe_by_joint_cm = metrics[m].pe_by_joint();
      r.height_error_by_joint_cm = metrics[m].height_error_by_joint();
    }
    // Nearest rank (bodyd/base/percentile.h); NaN, written as null, for a method that never ran.
    r.ms_per_frame_p50 = percentile(times[m], 0.5).value_or(std::numeric_limits<double>::quiet_NaN());
    r.ms_per_frame_p99 = percentile(times[m], 0.99).value_or(std::numeric_limits<double>::quiet_NaN());
    r.unanswered_frames = unanswered[m];
    report.methods.push_back(r);
    if (options.methods[m] == "diffusion") timed = m;
  }
  if (!metrics.empty()) {
    report.ground_truth = metrics[0].truth_result();
    report.ground_truth_jitter_by_joint_m_s3 = metrics[0].truth_jitter_by_joint();
  }
  for (size_t c = 0; c < 3; ++c)
    for (const auto& [name, g] : groups[c]) {
      GroupReport r;
      r.category = kCategories[c];
      r.name = name;
      r.clips = g.clips;
      r.frames = g.frames;
      for (size_t m = 0; m < options.methods.size(); ++m) {
        MethodReport mr;
        mr.name = options.methods[m];
        mr.metrics = g.methods[m].result();
        r.methods.push_back(mr);
      }
      r.ground_truth = g.methods[0].truth_result();
      report.groups.push_back(std::move(r));
    }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  report.calibration_error_cm = report.calibrated_clips > 0 ? calibration_error_sum_cm / report.calibrated_clips : nan;
  report.calibration_scale_error = report.calibrated_clips > 0 ? scale_error_sum / report.calibrated_clips : nan;
  report.calibration_time_s = report.calibrated_clips > 0 ? calibration_time_sum_s / report.calibrated_clips : nan;
  if (report.calibrated_clips == 0) report.calibration_scale_error_max = nan;
  if (report.device_frames) {
    divide_error(report.default_mounting_error, report.clips);
    divide_error(report.calibrated_mounting_error, report.pose_calibrated_clips);
    report.pose_calibration_time_s = report.pose_calibrated_clips > 0 ? pose_time_sum_s / report.pose_calibrated_clips : nan;
  }
  report.timing_method = report.methods[timed].name;
  report.ms_per_frame_p50 = report.methods[timed].ms_per_frame_p50;
  report.ms_per_frame_p99 = report.methods[timed].ms_per_frame_p99;
  return report;
}

namespace {

nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

void metric_fields(const AccuracyMetrics& m, nlohmann::ordered_json& o) {
  for (const MetricKey& k : kMetricKeys) o[std::string(k.key)] = number(m.*k.field);
  for (const MetricKey& k : kExtraMetricKeys) o[std::string(k.key)] = number(m.*k.field);
}

nlohmann::ordered_json by_joint(const std::vector<std::pair<std::string, double>>& values) {
  nlohmann::ordered_json o = nlohmann::ordered_json::object();
  for (const auto& [joint, value] : values) o[joint] = number(value);
  return o;
}

nlohmann::ordered_json truth_fields(const MotionQuality& q) {
  nlohmann::ordered_json o;
  o["jitter_m_s3"] = number(q.jitter_m_s3);
  o["foot_skate_ratio"] = number(q.foot_skate_ratio);
  o["gap_jerk_m_s3"] = number(q.gap_jerk_m_s3);
  return o;
}

}  // namespace

std::string report_json(const EvalReport& report) {
  nlohmann::ordered_json doc;
  doc["trackers"] = report.trackers;
  doc["clips"] = report.clips;
  doc["frames"] = report.frames;
  nlohmann::ordered_json methods = nlohmann::ordered_json::object();
  for (const MethodReport& m : report.methods) {
    nlohmann::ordered_json o;
    metric_fields(m.metrics, o);
    o["ms_per_frame_p50"] = number(m.ms_per_frame_p50);
    o["ms_per_frame_p99"] = number(m.ms_per_frame_p99);
    o["jitter_by_joint_m_s3"] = by_joint(m.jitter_by_joint_m_s3);
    o["pe_by_joint_cm"] = by_joint(m.pe_by_joint_cm);
    o["height_error_by_joint_cm"] = by_joint(m.height_error_by_joint_cm);
    methods[m.name] = o;
  }
  doc["methods"] = methods;
  doc["ground_truth"] = truth_fields(report.ground_truth);
  doc["ground_truth"]["jitter_by_joint_m_s3"] = by_joint(report.ground_truth_jitter_by_joint_m_s3);
  doc["timing"] = {{"ms_per_frame_p50", number(report.ms_per_frame_p50)},
                   {"ms_per_frame_p99", number(report.ms_per_frame_p99)}};
  nlohmann::ordered_json groups = nlohmann::ordered_json::object();
  for (const char* category : {"dataset", "content", "style"}) groups[category] = nlohmann::ordered_json::object();
  for (const GroupReport& g : report.groups) {
    nlohmann::ordered_json o;
    o["clips"] = g.clips;
    o["frames"] = g.frames;
    nlohmann::ordered_json ms = nlohmann::ordered_json::object();
    for (const MethodReport& m : g.methods) metric_fields(m.metrics, ms[m.name]);
    o["methods"] = ms;
    o["ground_truth"] = truth_fields(g.ground_truth);
    groups[g.category][g.name] = o;
  }
  doc["groups"] = groups;
  doc["body_scale"] = report.body_scale;
  doc["calibration"] = {{"enabled", report.calibrate},
                        {"clips_calibrated", report.calibrated_clips},
                        {"clips_fallback", report.fallback_clips},
                        {"head_height_error_cm", report.calibrate ? number(report.calibration_error_cm) : nullptr},
                        {"scale_error", report.calibrate ? number(report.calibration_scale_error) : nullptr},
                        {"scale_error_max", report.calibrate ? number(report.calibration_scale_error_max) : nullptr},
                        {"time_s", report.calibrate ? number(report.calibration_time_s) : nullptr}};
  if (report.device_frames) {
    const auto err = [](const EvalReport::MountingError& e) {
      return nlohmann::ordered_json{{"head_deg", number(e.head_deg)},
                                    {"head_pitch_deg", number(e.head_pitch_deg)},
                                    {"grip_deg", number(e.grip_deg)},
                                    {"eye_offset_cm", number(e.eye_offset_cm)},
                                    {"grip_offset_cm", number(e.grip_offset_cm)},
                                    {"body_deg", number(e.body_deg)},
                                    {"body_offset_cm", number(e.body_offset_cm)}};
    };
    nlohmann::ordered_json d;
    d["pose_calibration"] = report.calibrate_pose;
    d["clips_pose_calibrated"] = report.pose_calibrated_clips;
    d["pose_calibration_time_s"] = report.calibrate_pose ? number(report.pose_calibration_time_s) : nullptr;
    d["default_mounting_error"] = err(report.default_mounting_error);
    d["calibrated_mounting_error"] = report.calibrate_pose ? err(report.calibrated_mounting_error) : nullptr;
    d["body_trackers_unmeasured"] = report.body_trackers_unmeasured;
    doc["device_frames"] = d;
  }
  return doc.dump(2) + "\n";
}

std::string report_table(const EvalReport& report) {
  std::string out = fmt::format("{} clips, {} frames\n", report.clips, report.frames);
  out += fmt::format("{:<18}", "metric");
  for (const MethodReport& m : report.methods) out += fmt::format("{:>12}", m.name);
  out += fmt::format("{:>14}\n", "ground truth");
  std::vector<MetricKey> keys(kMetricKeys.begin(), kMetricKeys.end());
  keys.insert(keys.end(), kExtraMetricKeys.begin(), kExtraMetricKeys.end());
  for (const MetricKey& k : keys) {
    out += fmt::format("{:<18}", k.key);
    for (const MethodReport& m : report.methods) out += fmt::format("{:>12.4f}", m.metrics.*k.field);
    if (k.key == "jitter_m_s3")
      out += fmt::format("{:>14.4f}", report.ground_truth.jitter_m_s3);
    else if (k.key == "foot_skate_ratio")
      out += fmt::format("{:>14.4f}", report.ground_truth.foot_skate_ratio);
    else if (k.key == "gap_jerk_m_s3")
      out += fmt::format("{:>14.4f}", report.ground_truth.gap_jerk_m_s3);
    out += "\n";
  }
  out += fmt::format("{:<18}", "ms/frame p50");
  for (const MethodReport& m : report.methods) out += fmt::format("{:>12.4f}", m.ms_per_frame_p50);
  out += fmt::format("\n{:<18}", "ms/frame p99");
  for (const MethodReport& m : report.methods) out += fmt::format("{:>12.4f}", m.ms_per_frame_p99);
  out += "\n";
  for (const MethodReport& m : report.methods)
    if (m.unanswered_frames > 0)
      out += fmt::format("note: {} had no pose for {} frames (scored with its previous pose)\n", m.name,
                         m.unanswered_frames);
  if (report.calibrate)
    out += fmt::format(
        "body scale {}: calibrated on {} of {} clips ({} by the fallback), standing head height error {:.2f} cm, "
        "scale error {:.2f}% (mean; max {:.2f}%), {:.2f} s after the clip's start (mean)\n",
        report.body_scale, report.calibrated_clips, report.clips, report.fallback_clips, report.calibration_error_cm,
        100.0 * report.calibration_scale_error, 100.0 * report.calibration_scale_error_max, report.calibration_time_s);
  if (report.device_frames) {
    const auto line = [](const char* what, const EvalReport::MountingError& e) {
      return fmt::format("{} mounting error: head {:.2f} deg (pitch {:.2f}), grips {:.2f} deg, eye offset {:.2f} cm, "
                         "grip offset {:.2f} cm\n",
                         what, e.head_deg, e.head_pitch_deg, e.grip_deg, e.eye_offset_cm, e.grip_offset_cm);
    };
    out += "device frames: " + line("default", report.default_mounting_error);
    if (report.calibrate_pose && report.calibrated_mounting_error.body_n > 0)
      out += fmt::format("device frames: body trackers' calibrated mountings: {:.2f} deg, offset {:.2f} cm (mean over {} "
                         "tracker-clips; {} not measured, so not used)\n",
                         report.calibrated_mounting_error.body_deg, report.calibrated_mounting_error.body_offset_cm,
                         static_cast<long>(report.calibrated_mounting_error.body_n), report.body_trackers_unmeasured);
    if (report.calibrate_pose)
      out += fmt::format("device frames: calibration pose on {} of {} clips ({:.2f} s after the first sample); ",
                         report.pose_calibrated_clips, report.clips, report.pose_calibration_time_s) +
             line("calibrated", report.calibrated_mounting_error);
  }
  // Groups, compact: mpjpe, lower and head error per method, then the jitter ratio to the truth.
  if (!report.groups.empty()) {
    out += fmt::format("\n{:<28}{:>6}", "group", "clips");
    for (const MethodReport& m : report.methods)
      out += fmt::format("{:>10}{:>10}{:>9}", m.name.substr(0, 9), "lower", "jit/gt");
    out += "\n";
    for (const GroupReport& g : report.groups) {
      out += fmt::format("{:<28}{:>6}", (g.category + " " + g.name).substr(0, 27), g.clips);
      for (const MethodReport& m : g.methods)
        out += fmt::format("{:>10.2f}{:>10.2f}{:>9.2f}", m.metrics.mpjpe_cm, m.metrics.lower_pe_cm,
                           m.metrics.jitter_m_s3 / g.ground_truth.jitter_m_s3);
      out += "\n";
    }
    out += "(per method: mpjpe_cm, lower_pe_cm, jitter_m_s3 / ground truth's)\n";
  }
  return out;
}

}  // namespace bodyd
