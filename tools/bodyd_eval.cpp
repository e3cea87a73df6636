// bodyd-eval: accuracy of the reconstruction methods on motion-capture clips under the
// online protocol of docs/conventions.md (docs/evaluation.md).
//
//   bodyd-eval --model MODEL --json OUT.json [--seed N] [--noise-mm S] [--dropout-rate P]
//              [the simulator's other options: docs/simulator.md]
//              [--body-scale S] [--out-dir DIR] [--methods diffusion,ik] [--split FILE.txt] [FILE.bvh...]
//              [--no-body-filter | --body-filter-min-cutoff-hz F --body-filter-beta B ...] [--contact-on V] ...
#include "bodyd/base/random.h"
#include "bodyd/base/user_error.h"
#include "bodyd/inference/diffusion.h"
#include "bodyd/inference/evaluation.h"
#include "bodyd/inference/filter_option_keys.h"
#include "bodyd/motion/split_file.h"
#include "bodyd/simulators/sim_flags.h"
#include "bodyd/simulators/tracker_sim.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

namespace {

// SplitMix64 (bodyd/base/random.h): decorrelates the per-clip seeds derived from one run seed.
std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t clip_index) { return bodyd::splitmix64_at(seed, clip_index); }

std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bodyd-eval: evaluates reconstruction methods on BVH clips with simulated trackers, online and causal "
               "(docs/evaluation.md)"};
  std::string model, json_path, methods_text = "diffusion,ik", split;
  std::string out_dir;
  // The simulated trackers: the simulator's own flags (sim_option_keys()); a rate of 0 samples
  // each clip at its frame rate, and --seed seeds every clip's own seed.
  bodyd::SimOptions sim;
  sim.rate_hz = 0.0;
  std::optional<double> body_scale;
  std::vector<std::string> files;
  bodyd::ReconstructorOptions method_options;
  app.add_option("--model", model, "model file (needed by the diffusion method)");
  app.add_option("--json", json_path, "write the report as JSON to this file");
  bodyd::add_sim_flags(app, sim);
  app.get_option("--rate-hz")->description("tracker sample rate, Hz (0: the clip's frame rate)");
  app.get_option("--seed")->description("seed of the simulated tracker noise and dropout (each clip's is drawn from it)");
  app.add_option("--body-scale", body_scale,
                 "scale every clip by S (offsets and translations) to act a user S x the data's size; the "
                 "methods but ik then calibrate from the first still second, as the daemon's auto calibration")
      ->check(CLI::Range(0.3, 3.0));
  app.add_option("--out-dir", out_dir,
                 "write each clip's reconstruction as <clip>.pred.bvh (diffusion) and <clip>.<method>.pred.bvh");
  app.add_option("--methods", methods_text, "comma-separated methods (diffusion, ik)")->capture_default_str();
  app.add_option("--steps", method_options.diffusion_steps, "diffusion: DDIM steps per frame")
      ->capture_default_str()->check(CLI::Range(1, 1000));
  app.add_option("--guidance", method_options.guidance, "diffusion: classifier-free guidance scale (1 = off)")
      ->capture_default_str()->check(CLI::Range(0.0, 20.0));
  std::string weights_text;
  app.add_option("--weights", weights_text,
                 fmt::format("diffusion: the network's online weights, f32 or bf16 (default {}; docs/model.md, \"Weights in bf16\")",
                             bodyd::inference::weights_name(bodyd::DiffusionOptions{}.weights)))
      ->check(CLI::IsMember({"f32", "bf16"}));
  // The tracker filter and the body filter: one flag per row of the filters' table, the rows of the
  // daemon's "filter" and "body_filter" keys (filter_option_keys.h; docs/evaluation.md).
  bodyd::FilterSettings filters{method_options.filter, method_options.body_filter};
  std::map<std::string, CLI::Option*> filter_flags;  // by full key name ("body_filter.enabled")
  for (const bodyd::FilterOptionKey& row : bodyd::filter_option_keys()) {
    std::string names = bodyd::filter_flag(row);
    if (!row.eval_aliases.empty()) names += "," + std::string(row.eval_aliases);
    const std::string help = fmt::format("diffusion: {} (the daemon's \"{}\", docs/daemon.md)", row.help, row.full_name());
    CLI::Option* option = std::visit(
        [&](auto field) -> CLI::Option* {
          auto& member = field(filters);
          if constexpr (std::is_same_v<std::remove_reference_t<decltype(member)>, bool>)
            return app.add_flag(names, member, help);
          else
            return app.add_option(names, member, help)->capture_default_str();
        },
        row.field);
    if (row.group == "body_filter" && row.name != "enabled") option->excludes(filter_flags.at("body_filter.enabled"));
    filter_flags[row.full_name()] = option;
  }
  // The foot lock's knobs (DiffusionOptions, diffusion.h); unset: its defaults. CLI11's range
  // checks let NaN through, hence the finite check.
  const CLI::Validator finite(
      [](const std::string& text) {
        double v = 0;
        return CLI::detail::lexical_cast(text, v) && std::isfinite(v) ? std::string{} : "must be a finite number";
      },
      "FINITE");
  // The help shows DiffusionOptions' own defaults, so a re-chosen default cannot leave it behind.
  const bodyd::DiffusionOptions defaults;
  const auto knob = [&](const char* flag, auto& member, std::string_view what, auto default_value,
                        const CLI::Validator& range) {
    app.add_option(flag, member, fmt::format("diffusion: {} (default {})", what, default_value))->check(finite)->check(range);
  };
  knob("--contact-on", method_options.contact_on, "a free foot plants when its predicted contact exceeds this",
       defaults.contact_on, CLI::Range(0.0, 1.0));
  knob("--contact-off", method_options.contact_off, "a planted foot stays planted while its predicted contact exceeds this",
       defaults.contact_off, CLI::Range(0.0, 1.0));
  knob("--foot-unlock-distance-m", method_options.foot_unlock_distance_m,
       "a planted foot further than this from its prediction re-plants there, m", defaults.foot_unlock_distance_m,
       CLI::NonNegativeNumber);
  knob("--foot-release-half-life-s", method_options.foot_release_half_life_s,
       "a lifted foot eases from its planted spot to the prediction with this half-life, s",
       defaults.foot_release_half_life_s, CLI::PositiveNumber);
  knob("--foot-contact-speed-m-s", method_options.foot_contact_speed_m_s,
       "a planted toe follows the prediction at most this fast, m/s", defaults.foot_contact_speed_m_s,
       CLI::NonNegativeNumber);
  knob("--leg-position-blend", method_options.leg_position_blend,
       "each leg is bent so its ankle moves this fraction of the way from where the joint rotations put it to the "
       "ankle position the network predicts (0-1)",
       defaults.leg_position_blend, CLI::Range(0.0, 1.0));
  knob("--elbow-pole-bias-m", method_options.elbow_pole_bias_m,
       "the arms' elbow pole is the predicted elbow pushed this far outward, down and back, m", defaults.elbow_pole_bias_m,
       CLI::Range(0.0, 10.0));
  std::string device_frames = "joint", calibration_pose = "first-still", reference_path;
  bool method_pose_eye = false;
  bodyd::add_device_frames_flag(app, device_frames,
      "joint: the trackers are the skeleton's joints (default); xr: what a headset and controllers send "
      "(the headset at the eyes in the XR axes, the controllers' grip poses, a random mounting per clip), "
      "mapped through the default mounting and the calibration pose (docs/evaluation.md)");
  app.add_option("--calibration-pose", calibration_pose,
                 "with --device-frames xr: first-still (the clip's first still second, default), none (the default "
                 "mounting only), a frame number N (that frame's pose held for 1.2 s before the clip starts), reference (the "
                 "user stands in the calibration pose as the body reference describes it for 1.05 s before the clip, at its "
                 "first head position and heading), person (the same pose as one person stands it: the head and wrists off "
                 "the reference by normal draws of the reference's spreads over the training takes), or truth (analysis: the true mounting, what a perfect calibration "
                 "gives)")
      ->capture_default_str();
  app.add_flag("--estimate-eye-offset", method_pose_eye,
               "with a calibration pose: also estimate the eye offset from the wrists (docs/evaluation.md)");
  bool head_roll = false;
  app.add_flag("--head-roll", head_roll,
               "with a calibration pose: learn the headset's roll on the head too, not only its pitch (docs/evaluation.md)");
  app.add_option("--reference", reference_path, "body reference of the default mounting (default: data/body-reference.json)");
  bodyd::add_trackers_flag(app, sim);
  app.add_option("--split", split, "split file: BVH paths relative to its folder's parent (e.g. splits/val.txt)");
  app.add_option("files", files, "BVH files (besides or instead of --split)");
  CLI11_PARSE(app, argc, argv);
  {
    bodyd::SimOptions check = sim;
    if (check.rate_hz == 0.0) check.rate_hz = 90.0;  // each clip's frame rate, checked when it is read
    if (const std::string e = check.validate(); !e.empty()) {
      fmt::print(stderr, "bodyd-eval: bad option: {}\n", e);
      return 2;
    }
  }
  spdlog::set_default_logger(spdlog::stderr_color_mt("bodyd-eval"));  // stdout holds the table

  try {
    std::vector<std::filesystem::path> clips;
    if (!split.empty()) clips = bodyd::read_split(split);
    for (const std::string& f : files) clips.emplace_back(f);
    if (clips.empty()) throw bodyd::UserError("", "no clips", "give BVH files or --split FILE.txt");

    bodyd::EvalOptions options;
    options.trackers = bodyd::tracker_set_text({sim.roles, sim.rotation_only});
    options.methods = split_list(methods_text);
    if (options.methods.empty()) throw bodyd::UserError("--methods", "names no method", "give diffusion, ik or both");
    options.model_path = model;
    if (const std::string e = bodyd::validate(method_options.filter); !e.empty())
      throw bodyd::UserError("", e, "see the --filter-* flags' ranges in docs/daemon.md, \"Tracker filter\"");
    // --body-filter-min-cutoff-hz alone sets the rotations' cutoff too (as it always has here).
    if (filter_flags.at("body_filter.min_cutoff_hz")->count() > 0 && filter_flags.at("body_filter.rot_min_cutoff_hz")->count() == 0)
      method_options.body_filter.rot_min_cutoff_hz = method_options.body_filter.min_cutoff_hz;
    if (const std::string e = bodyd::validate(method_options.body_filter); !e.empty())
      throw bodyd::UserError("", e, "see the --body-filter-* flags' ranges in docs/daemon.md, \"Body filter\"");
    if (!weights_text.empty()) method_options.weights = bodyd::inference::parse_weights(weights_text);
    options.reconstructor = method_options;
    if (!out_dir.empty()) options.out_dir = out_dir;
    if (body_scale) {
      options.body_scale = *body_scale;
      options.calibrate = true;
    }
    options.on_clip = [](int i, int n, const std::filesystem::path& p) {
      spdlog::info("clip {}/{}: {}", i + 1, n, p.filename().string());
    };

    std::optional<int> hold_frame;
    if (device_frames == "xr") {
      options.device_frames = true;
      options.body_reference = bodyd::read_body_reference(bodyd::find_body_reference(reference_path));
      options.pose_calibration.estimate_eye_offset = method_pose_eye;
      options.pose_calibration.estimate_head_roll = head_roll;
      if (calibration_pose == "truth") options.oracle_mounting = true;
      else if (calibration_pose != "none") options.calibrate_pose = true;
      if (calibration_pose != "none" && calibration_pose != "first-still" && calibration_pose != "truth" &&
          calibration_pose != "reference" && calibration_pose != "person") {
        int frame = -1;
        const char* end = calibration_pose.data() + calibration_pose.size();
        const auto [at, ec] = std::from_chars(calibration_pose.data(), end, frame);
        if (ec != std::errc() || at != end || frame < 0)
          throw bodyd::UserError("--calibration-pose " + calibration_pose, "not a choice or a frame number",
                                 "give first-still, none, reference, person, truth or a frame number (0, 1, ...)");
        hold_frame = frame;
      }
    } else if (calibration_pose != "first-still") {
      throw bodyd::UserError("--calibration-pose " + calibration_pose, "needs device frames",
                             "add --device-frames xr");
    }
    const bodyd::Mounting defaults = bodyd::default_mounting(options.body_reference);
    const auto session_mounting = [&](int index) {
      return bodyd::draw_session_mounting(defaults, bodyd::MountingSpread{}, mix_seed(sim.seed, static_cast<std::uint64_t>(index)));
    };
    if (options.device_frames) options.true_mounting = session_mounting;
    const bodyd::TrackerSource source = [&](const bodyd::Motion& clip, int index) {
      bodyd::SimOptions o = sim;
      o.rate_hz = sim.rate_hz > 0.0 ? sim.rate_hz : clip.fps();  // default: at the frame times (docs/evaluation.md)
      o.seed = mix_seed(sim.seed, static_cast<std::uint64_t>(index));
      if (options.device_frames) o.device_mounting = session_mounting(index);
      std::vector<bodyd::TrackerSample> samples = bodyd::simulate_trackers(clip, o);
      if (calibration_pose == "reference" || calibration_pose == "person") {
        std::optional<std::uint64_t> vary;
        if (calibration_pose == "person") vary = o.seed;
        samples = bodyd::with_calibration_pose(samples, options.body_reference, *o.device_mounting, o.rate_hz, 1.05, vary);
      } else if (hold_frame) {
        // The calibration pose: frame N's device poses held still for 1.2 s before the clip.
        if (*hold_frame >= clip.frame_count())
          throw bodyd::UserError(fmt::format("--calibration-pose {}", *hold_frame),
                                 fmt::format("the clip has {} frames", clip.frame_count()),
                                 "hold a frame every clip has (0 is the first)");
        // The clip's joints at frame N (its truth), held still, seen through the session mounting.
        const bodyd::TrackerTrajectory trajectory(clip);
        const std::int64_t t_frame = std::llround(*hold_frame * clip.frame_time_s * 1e9);
        std::array<bodyd::RigidTransform, bodyd::kRoleCount> joints;
        for (bodyd::Role r : bodyd::kRoles) joints[static_cast<std::size_t>(r)] = bodyd::pose_of(trajectory.pose_at(r, t_frame));
        samples = bodyd::with_held_pose(samples, joints, *o.device_mounting, o.rate_hz, 1.2, /*body_roles=*/true);
      }
      return samples;
    };

    const bodyd::EvalReport report = bodyd::evaluate(clips, options, source);
    // A NaN or infinite metric is never printed as a result (issue 11: a clip with finite but
    // absurd values once gave "nan" and exit 0). The BVH reader keeps values in range, so
    // this is the last wall, against clips too short for a metric and against bugs.
    auto require_finite = [](double v, const std::string& what) {
      if (!std::isfinite(v))
        throw bodyd::UserError(what, fmt::format("is {}: no result is printed", v),
                               "a metric is undefined when every clip is too short for it (jitter needs 4 frames, "
                               "velocities 2); otherwise a clip holds values the metrics cannot use, so check the "
                               "clips with bodyd-bvh, and report it if they read fine");
    };
    for (const bodyd::MethodReport& m : report.methods)
      for (const bodyd::MetricKey& k : bodyd::kMetricKeys)
        require_finite(m.metrics.*k.field, fmt::format("metric {} of method {}", k.key, m.name));
    require_finite(report.ground_truth.jitter_m_s3, "ground truth's jitter_m_s3");
    require_finite(report.ground_truth.foot_skate_ratio, "ground truth's foot_skate_ratio");
    const std::string json = bodyd::report_json(report);
    if (!json_path.empty()) {
      std::ofstream out(json_path);
      out << json;
      if (!out) throw bodyd::UserError(json_path, "cannot write the JSON report", "check the folder exists and is writable");
    }
    fmt::print("{}", bodyd::report_table(report));
    fmt::print("timing ({}): p50 {:.4f} ms, p99 {:.4f} ms per frame\n", report.timing_method,
               report.ms_per_frame_p50, report.ms_per_frame_p99);
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "bodyd-eval: error: {}\n", e.what());
    return 1;
  }
}
