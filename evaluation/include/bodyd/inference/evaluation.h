// The online evaluation (docs/conventions.md "Online evaluation protocol"; docs/evaluation.md):
// tracker samples of a clip are fed sample by sample to a fresh Reconstructor per method, the
// pose is requested at every frame time with only the samples up to that time pushed, and
// every frame is scored against the clip's forward kinematics.
//
// This library does not simulate trackers itself: the caller passes a TrackerSource (bodyd-eval
// uses the simulator of simulators/), so tests can feed any stream.
#pragma once

#include "bodyd/inference/calibration.h"
#include "bodyd/inference/metrics.h"
#include "bodyd/inference/factory.h"
#include "bodyd/inference/reconstructor.h"
#include "bodyd/motion/bvh.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace bodyd {

// Frame k of a clip is at t = llround(k * (1e9 / fps)) ns, fps = 1 / frame_time_s: the same
// expression the tracker simulator uses for its sample times, so samples simulated at the
// clip's frame rate fall exactly on the frame times.
[[nodiscard]] std::vector<std::int64_t> clip_frame_times_ns(const Motion& clip);

// The outputs of one reconstructor over one stream.
struct OnlineRun {
  std::vector<BodyPose> poses;        // one per frame time
  std::vector<bool> answered;         // reconstruct() returned true for that frame
  std::vector<double> ms_per_frame;   // wall time of each reconstruct() call, milliseconds
  int unanswered = 0;                 // frames where reconstruct() returned false
};

// The online protocol for one reconstructor: for each frame time (increasing), push every
// sample with t_ns <= frame time + lookahead_ns not pushed yet (in the order given, which must
// be sorted by time), then reconstruct(frame time). The evaluation uses lookahead 0; a positive
// lookahead hands the reconstructor samples newer than the requested time, as a live daemon may
// (the causality check uses it). A frame where reconstruct() returns false gets the previous
// frame's pose, and frames before the first answer get the first answer (so every frame can be
// scored; `unanswered` counts them). Does not reset `reconstructor` first.
[[nodiscard]] OnlineRun run_online(Reconstructor& reconstructor, std::span<const TrackerSample> samples,
                                   std::span<const std::int64_t> frame_times_ns, std::int64_t lookahead_ns = 0);

// Causality check, reusable for any Reconstructor: runs a fresh reconstructor (from `make`) on
// `samples`, then another on a copy where every sample later than `t_star_ns` is changed
// (positions moved by 0.3 m, rotations turned by 60 degrees, validity flipped on every third),
// and compares the outputs frame by frame. Both runs push samples `lookahead_ns` ahead of each
// requested time (run_online), so a reconstructor that looks at samples newer than the requested
// time is caught. Outputs for frames at or before t_star must be bit-identical (rotations,
// translations, contacts, tracker validity).
struct CausalityReport {
  bool causal = true;            // no difference at or before t_star
  int frames_checked = 0;        // frames at or before t_star
  int first_violation = -1;      // frame index of the first difference, or -1
  bool future_changed = false;   // some frame after t_star differs (the perturbation took effect)
  std::string message;           // what differed, where (empty when causal)
};
[[nodiscard]] CausalityReport check_causality(const std::function<std::unique_ptr<Reconstructor>()>& make,
                                              std::span<const TrackerSample> samples,
                                              std::span<const std::int64_t> frame_times_ns, std::int64_t t_star_ns,
                                              std::int64_t lookahead_ns = 500'000'000);

// Tracker samples for clip number `clip_index` (sorted by time). bodyd-eval's source simulates
// them from the clip (noise, dropout) with a seed derived from the run's seed and clip_index.
using TrackerSource = std::function<std::vector<TrackerSample>(const Motion& clip, int clip_index)>;

struct EvalOptions {
  std::string trackers = "head,left_hand,right_hand";  // the tracker set the source simulates (reported)
  std::vector<std::string> methods{"diffusion", "ik"};
  std::filesystem::path model_path;         // for methods that need a model
  ReconstructorOptions reconstructor;       // method options (diffusion steps, guidance, seed)
  std::optional<std::filesystem::path> out_dir;  // write <clip>.pred.bvh / <clip>.<method>.pred.bvh
  // Each clip is scaled by body_scale (skeleton offsets and every translation) before trackers are
  // simulated and truth is computed, to act a user body_scale x the data's size.
  double body_scale = 1.0;
  // Calibrate every method but "ik" (which is given the clip's own skeleton) as the daemon's auto
  // calibration does (its body pipeline, body_pipeline.h): a StandingHeightDetector over the head
  // samples, then calibrate_from_head_height() at the sample that completes the first still stretch.
  bool calibrate = false;
  StandingHeightOptions calibration;
  // Device frames (docs/evaluation.md "Device frames"): the source's samples are device poses
  // (a headset at the eyes, controllers' grips) and every method maps them to joints through a
  // mounting, in the daemon's body pipeline: the default from `body_reference`, and with
  // `calibrate_pose` the one a PoseCalibrator measures from the clip's first still second, as a
  // calibration pose held from the start (with `calibrate`, its height is applied too, instead of
  // the StandingHeightDetector's). `true_mounting` gives the mounting the
  // source used for a clip, to report the estimate's error.
  bool device_frames = false;
  BodyReference body_reference;
  bool calibrate_pose = false;
  PoseCalibrationOptions pose_calibration;
  std::function<Mounting(int clip_index)> true_mounting;
  // Analysis only: map through the true mounting (what a perfect calibration would give).
  bool oracle_mounting = false;
  // Called after each clip (for progress); may be empty.
  std::function<void(int clip_index, int clip_count, const std::filesystem::path& clip)> on_clip;
};

struct MethodReport {
  std::string name;
  AccuracyMetrics metrics;
  double ms_per_frame_p50 = 0.0;
  double ms_per_frame_p99 = 0.0;
  std::int64_t unanswered_frames = 0;
  // jitter_m_s3 joint by joint (MetricsAccumulator::jitter_by_joint; whole report only, empty in groups).
  std::vector<std::pair<std::string, double>> jitter_by_joint_m_s3;
  // The position error and its signed height component joint by joint, cm
  // (MetricsAccumulator::pe_by_joint, height_error_by_joint; whole report only, empty in groups).
  std::vector<std::pair<std::string, double>> pe_by_joint_cm;
  std::vector<std::pair<std::string, double>> height_error_by_joint_cm;
};

// The results of the clips of one group (docs/evaluation.md, "Groups").
struct GroupReport {
  std::string category;  // "dataset", "content" or "style"
  std::string name;      // e.g. "dataset-1", "walk", "normal"; "other" for an unparsed file name
  int clips = 0;
  std::int64_t frames = 0;
  std::vector<MethodReport> methods;  // metrics only (no timing)
  MotionQuality ground_truth;
};

// The groups of a clip from its file name dataset-N_{content}_{style}_{take}.bvh: {dataset,
// content, style}; {"other", "other", "other"} for a name of another shape.
[[nodiscard]] std::array<std::string, 3> clip_groups(const std::filesystem::path& clip);

// A copy of `clip` scaled by `s`: skeleton offsets, end sites and every frame's local
// translations multiplied by s (rotations unchanged).
[[nodiscard]] Motion scale_motion(const Motion& clip, double s);

struct EvalReport {
  std::string trackers;  // EvalOptions::trackers
  int clips = 0;
  std::int64_t frames = 0;
  std::vector<MethodReport> methods;  // in the order of EvalOptions::methods
  MotionQuality ground_truth;
  std::vector<std::pair<std::string, double>> ground_truth_jitter_by_joint_m_s3;
  // Per group, by category ("dataset", "content", "style") then name, in sorted order.
  std::vector<GroupReport> groups;
  double body_scale = 1.0;
  bool calibrate = false;
  // With calibrate: clips where the detector found a standing height (a still stretch or the fallback) (per calibrated method,
  // the same for each), and the mean |measured - true| standing head height over them, cm (the
  // true one: standing_head_height_m() of the scaled clip's skeleton).
  int calibrated_clips = 0;
  int fallback_clips = 0;              // of those, calibrated by the detector's fallback estimate
  double calibration_error_cm = 0.0;
  double calibration_scale_error = 0.0;      // mean |measured / true - 1| (0.01: 1%)
  double calibration_scale_error_max = 0.0;  // the largest
  double calibration_time_s = 0.0;     // mean time from a clip's first frame to its calibration
  // With device_frames: the mean error of the mounting each method used against the truth, for
  // the default mounting and (calibrate_pose) for the calibrated one over the clips it calibrated.
  bool device_frames = false;
  bool calibrate_pose = false;
  int pose_calibrated_clips = 0;
  struct MountingError {
    double head_deg = 0.0;        // headset rotation on the head
    double head_pitch_deg = 0.0;  // its pitch part (about the device's +X)
    double grip_deg = 0.0;        // controllers' grip rotation (mean of both hands)
    double eye_offset_cm = 0.0;   // the head's T_device_joint position
    double grip_offset_cm = 0.0;  // the hands' T_device_joint position (mean of both)
    // Body trackers of the set (issue 44): rotation and offset, means over tracker-clips (NaN
    // without any; a rotation-only tracker's offset is not scored), and how many were scored.
    double body_deg = 0.0, body_offset_cm = 0.0;
    double body_n = 0.0, body_offset_n = 0.0;
  };
  MountingError default_mounting_error, calibrated_mounting_error;
  double pose_calibration_time_s = 0.0;  // mean time from a clip's first sample to its calibration
  long body_trackers_unmeasured = 0;     // tracker-clips whose calibration pose did not measure a body tracker
  // Timing of "diffusion" if evaluated, otherwise of the first method.
  std::string timing_method;
  double ms_per_frame_p50 = 0.0;
  double ms_per_frame_p99 = 0.0;
};

// Evaluates every clip with every method. Throws BvhError for an unreadable clip,
// ReconstructorError for a method that cannot be made, and a UserError whose where is the clip
// for anything else (a skeleton that differs from the first clip's or lacks a body joint, a
// method that never produced a pose on the clip, a tracker source that failed). No methods or a
// body scale <= 0 is a bug (BODYD_REQUIRE): the caller checks its options.
[[nodiscard]] EvalReport evaluate(std::span<const std::filesystem::path> clips, const EvalOptions& options,
                                  const TrackerSource& source);

// The report as the JSON document of docs/evaluation.md (NaN metrics as null), 2-space indented.
[[nodiscard]] std::string report_json(const EvalReport& report);
// A human-readable table of the report.
[[nodiscard]] std::string report_table(const EvalReport& report);

}  // namespace bodyd
