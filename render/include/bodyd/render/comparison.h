// A reconstruction next to its ground truth, ready to draw: the truth clip and each method's
// global joint positions frame by frame, checked to match (frame count, joint names), with
// per-frame errors and the docs/conventions.md metrics (computed by bodyd_inference's
// MetricsAccumulator; this file only adds per-frame distances).
//
// Errors the user can fix (unreadable file, wrong frame count, other skeleton) throw
// RenderError with the file and what to do.
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/inference/metrics.h"
#include "bodyd/motion/bvh.h"

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace bodyd::render {

class RenderError : public UserError {
 public:
  using UserError::UserError;
};

// One motion over the truth's frames: global joint transforms in the truth skeleton's joint order.
struct Track {
  std::string label;                 // legend text ("ground truth", "diffusion", "ik", ...)
  std::filesystem::path source;      // the file it came from
  std::vector<GlobalPose> frames;    // one per truth frame
};

// Per-frame mean joint distances (centimetres) of a prediction against the truth, over the joint
// sets of docs/conventions.md (all 21 body joints, lower body 9, hands 2).
struct FrameErrors {
  std::vector<double> all_cm;
  std::vector<double> lower_cm;
  std::vector<double> hands_cm;
};

struct MethodResult {
  Track track;
  FrameErrors errors;
  AccuracyMetrics metrics;  // MetricsAccumulator over the clip (NaN where undefined)
};

struct Comparison {
  std::string clip_name;  // the truth file's stem
  Skeleton skeleton;      // the truth's
  double fps = 30.0;
  Track truth;
  MotionQuality truth_quality;  // ground truth's own jitter and foot skating
  std::vector<MethodResult> methods;
  [[nodiscard]] int frame_count() const { return static_cast<int>(truth.frames.size()); }
};

// Where a prediction comes from.
struct PredictionSource {
  enum class Kind { kBvh, kRecording };
  Kind kind = Kind::kBvh;
  std::filesystem::path path;
  std::string label;  // empty: default_label()
};

// The legend label of a prediction file when none is given: bodyd-eval's names
// (docs/evaluation.md) `<clip>.pred.bvh` -> "diffusion", `<clip>.<method>.pred.bvh` -> method;
// a pose recording -> "recording"; any other file -> its stem.
[[nodiscard]] std::string default_label(const PredictionSource& source, const std::string& clip_name);

// Forward kinematics of every frame of a BVH motion.
[[nodiscard]] std::vector<GlobalPose> global_frames(const Motion& motion);

// Builds a prediction track from a BVH file: same joint names in the same order and the same frame
// count as `truth`, otherwise RenderError saying what differs.
[[nodiscard]] Track load_bvh_prediction(const std::filesystem::path& path, const Motion& truth, const std::string& label);

// Builds a prediction track from a pose recording (docs/pose-recording.md, e.g. bodyd-record of
// `bodyd --sim CLIP.bvh`). The poses' skeleton must have the truth's joint names. With exactly as
// many poses as truth frames they are taken one to one; otherwise they are resampled onto the
// truth's frame times by their t_ns, relative to the first pose: frame k shows the newest pose with
// t_ns - t_first <= k / fps + 0.5 / fps. A recording shorter than the clip is an error.
[[nodiscard]] Track load_recording_prediction(const std::filesystem::path& path, const Motion& truth,
                                              const std::string& label);

// Per-frame errors of `prediction` against `truth` (equal frame counts, else a bug; same joint order).
// Distances only; the joint sets come from bodyd::joint_sets().
[[nodiscard]] FrameErrors per_frame_errors(const JointSets& sets, const std::vector<GlobalPose>& prediction,
                                           const std::vector<GlobalPose>& truth);

// Loads the truth and every prediction, checks them and computes errors and metrics.
[[nodiscard]] Comparison load_comparison(const std::filesystem::path& truth_path,
                                         const std::vector<PredictionSource>& predictions);

// The same from tracks already in memory (the truth's skeleton and frames; each track checked).
[[nodiscard]] Comparison make_comparison(const std::string& clip_name, const Motion& truth, std::vector<Track> predictions);

}  // namespace bodyd::render
