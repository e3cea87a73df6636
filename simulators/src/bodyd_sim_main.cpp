// bodyd-sim: simulated tracker log (head + two hands) from a BVH clip.
// Options and models: docs/simulator.md; output format: docs/tracker-log.md.
#include "bodyd/base/user_error.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/tracker_log.h"
#include "bodyd/simulators/sim_flags.h"
#include "bodyd/simulators/tracker_sim.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <cstdio>
#include <filesystem>

int main(int argc, char** argv) {
  CLI::App app{
      "Simulates the tracker streams (head, left_hand, right_hand) of a headset and two controllers\n"
      "while a person performs a BVH clip, and writes them as a tracker log (docs/tracker-log.md).\n"
      "Poses are forward kinematics of the joints Head, Hand_L, Hand_R, interpolated between frames;\n"
      "frame k of the clip is at t_ns = k * frame_time. Noise, latency, jitter and dropout models:\n"
      "docs/simulator.md. The same --seed gives the same output.",
      "bodyd-sim"};
  std::string bvh_path, out_path;
  bodyd::SimOptions opt;
  double hands_rate_hz = 0.0;
  bool quiet = false;
  app.add_option("--bvh", bvh_path, "input BVH clip (centimetres)")->required();
  app.add_option("--out", out_path, "output tracker log (CSV); '-' writes to stdout")->required();
  // The simulator's options, one flag per row of sim_option_keys() (the older spellings too).
  bodyd::add_sim_flags(app, opt);
  app.add_option("--hands-rate-hz", hands_rate_hz, "both hands' sample rate, Hz (sets --left-hand-rate-hz and "
                                                   "--right-hand-rate-hz)");
  std::string device_frames = "joint", reference_path;
  bodyd::add_device_frames_flag(app, device_frames,
      "joint: the skeleton's joints (default); xr: what a headset and controllers send (the headset at the "
      "eyes in the XR axes, the controllers' grip poses), with a mounting drawn from the seed "
      "(docs/simulator.md)");
  app.add_option("--reference", reference_path, "body reference of the default mounting (default: the bundled data/body-reference.json)");
  bodyd::add_trackers_flag(app, opt);
  app.add_flag("--quiet,-q", quiet, "print no summary");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help exits 0; every usage error exits 2 (CLI11's own codes vary by error).
    return app.exit(e) == 0 ? 0 : 2;
  }

  if (app.count("--hands-rate-hz") > 0) {
    opt.role_rate_hz[static_cast<size_t>(bodyd::Role::LeftHand)] = hands_rate_hz;
    opt.role_rate_hz[static_cast<size_t>(bodyd::Role::RightHand)] = hands_rate_hz;
  }
  if (std::string err = opt.validate(); !err.empty()) {
    fmt::print(stderr, "bodyd-sim: bad option: {}\n", err);
    return 2;
  }

  try {
    const bodyd::Motion motion = bodyd::read_bvh(bvh_path);
    if (device_frames == "xr")
      opt.device_mounting = bodyd::draw_session_mounting(bodyd::default_mounting(bodyd::read_body_reference(
                                                             bodyd::find_body_reference(reference_path))),
                                                         bodyd::MountingSpread{}, opt.seed);
    const std::vector<bodyd::TrackerSample> samples = bodyd::simulate_trackers(motion, opt);
    bodyd::TrackerLogMetadata meta{
        {"generator", "bodyd-sim"},
        {"source", std::filesystem::path(bvh_path).filename().string()},
        {"frames", fmt::format("{}", motion.frame_count())},
        {"frame_time_s", fmt::format("{}", motion.frame_time_s)},
        {"rate_hz", fmt::format("head={} left_hand={} right_hand={}", opt.rate_of(bodyd::Role::Head),
                                opt.rate_of(bodyd::Role::LeftHand), opt.rate_of(bodyd::Role::RightHand))},
        {"noise", fmt::format("position_mm={} rotation_deg={}", opt.position_noise_mm, opt.rotation_noise_deg)},
        {"timing", fmt::format("latency_ms={} jitter_ms={}", opt.latency_ms, opt.jitter_ms)},
        {"dropout", fmt::format("rate_hz={} mean_ms={}", opt.dropout_rate_hz, opt.dropout_mean_ms)},
        {"seed", fmt::format("{}", opt.seed)},
    };
    if (opt.roles.size() != bodyd::kXrRoles.size() || !opt.rotation_only.empty())
      meta.emplace_back("trackers", bodyd::tracker_set_text({opt.roles, opt.rotation_only}));
    if (opt.device_mounting) {
      meta.emplace_back(std::string(bodyd::kTrackerLogPoseFrameKey), "device");
      meta.emplace_back("mounting_truth", bodyd::mounting_text(*opt.device_mounting));
    }
    if (out_path == "-") {
      const std::string text = bodyd::format_tracker_log(samples, meta);
      std::fwrite(text.data(), 1, text.size(), stdout);
      if (std::fflush(stdout) != 0) {
        fmt::print(stderr, "bodyd-sim: writing to stdout failed\n");
        return 1;
      }
    } else {
      bodyd::write_tracker_log(out_path, samples, meta);
    }
    if (!quiet) {
      // The summary goes to stderr when the log itself goes to stdout.
      std::FILE* sink = out_path == "-" ? stderr : stdout;
      fmt::print(sink, "{}: {} frames at {:.6g} fps ({:.3f} s) -> {} samples in {}\n", bvh_path,
                 motion.frame_count(), motion.fps(), (motion.frame_count() - 1) * motion.frame_time_s,
                 samples.size(), out_path);
      for (bodyd::Role r : opt.roles) {
        size_t n = 0, invalid = 0;
        for (const auto& s : samples)
          if (s.role == r) {
            ++n;
            if (!s.valid) ++invalid;
          }
        fmt::print(sink, "  {:<10} {:>7} samples at {:g} Hz, {} invalid ({:.1f}%)\n", bodyd::role_name(r), n,
                   opt.rate_of(r), invalid, n ? 100.0 * static_cast<double>(invalid) / static_cast<double>(n) : 0.0);
      }
    }
  } catch (const bodyd::SimError& e) {  // about the clip, which it does not name
    fmt::print(stderr, "bodyd-sim: {}: {}\n", bvh_path, e.what());
    return 1;
  } catch (const bodyd::UserError& e) {  // the BVH, body reference or tracker log, named
    fmt::print(stderr, "bodyd-sim: {}\n", e.what());
    return 1;
  }
  return 0;
}
