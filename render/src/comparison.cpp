#include "bodyd/render/comparison.h"

#include "bodyd/base/require.h"
#include "bodyd/protocol/recording.h"

#include <fmt/format.h>

#include <cmath>
#include <unordered_map>

namespace bodyd::render {
namespace {

bool ends_with(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// For every truth joint, its index among `names`; RenderError listing the joints `names` lacks.
std::vector<int> map_joints(const Skeleton& truth, const std::vector<std::string>& names, const std::filesystem::path& path,
                            const std::filesystem::path& truth_path) {
  std::unordered_map<std::string, int> index;
  for (int i = 0; i < static_cast<int>(names.size()); ++i) index.emplace(names[static_cast<size_t>(i)], i);
  std::vector<int> map(static_cast<size_t>(truth.size()), -1);
  std::string missing;
  for (int j = 0; j < truth.size(); ++j) {
    auto it = index.find(truth.names[static_cast<size_t>(j)]);
    if (it == index.end()) {
      missing += (missing.empty() ? "" : ", ") + truth.names[static_cast<size_t>(j)];
    } else {
      map[static_cast<size_t>(j)] = it->second;
    }
  }
  if (!missing.empty()) {
    throw RenderError(
        path.string(),
        fmt::format("its skeleton lacks joints of the ground truth {} ({})", truth_path.string(), missing),
        "a prediction must use the truth's skeleton (joint names)");
  }
  return map;
}

}  // namespace

std::string default_label(const PredictionSource& source, const std::string& clip_name) {
  if (source.kind == PredictionSource::Kind::kRecording) return "recording";
  const std::string name = source.path.filename().string();
  if (name == clip_name + ".pred.bvh") return "diffusion";
  const std::string prefix = clip_name + ".";
  if (name.size() > prefix.size() && name.compare(0, prefix.size(), prefix) == 0 && ends_with(name, ".pred.bvh")) {
    std::string method = name.substr(prefix.size(), name.size() - prefix.size() - std::string_view(".pred.bvh").size());
    if (!method.empty()) return method;
  }
  return source.path.stem().string();
}

std::vector<GlobalPose> global_frames(const Motion& motion) {
  std::vector<GlobalPose> out(motion.frames.size());
  for (size_t f = 0; f < motion.frames.size(); ++f) forward_kinematics(motion.skeleton, motion.frames[f], out[f]);
  return out;
}

Track load_bvh_prediction(const std::filesystem::path& path, const Motion& truth, const std::string& label) {
  Motion pred;
  try {
    pred = read_bvh(path);
  } catch (const BvhError& e) {
    throw RenderError(e.problem());
  }
  if (pred.frame_count() != truth.frame_count()) {
    throw RenderError(path.string(),
                      fmt::format("{} frames, but the ground truth has {}", pred.frame_count(), truth.frame_count()),
                      "a prediction must cover every frame of its clip (bodyd-eval --out-dir writes such files)");
  }
  const std::vector<int> map = map_joints(truth.skeleton, pred.skeleton.names, path, "the truth");
  std::vector<GlobalPose> pred_global = global_frames(pred);
  Track track{label, path, {}};
  track.frames.resize(pred_global.size());
  for (size_t f = 0; f < pred_global.size(); ++f) {
    GlobalPose& out = track.frames[f];
    out.positions.resize(map.size());
    out.rotations.resize(map.size());
    for (size_t j = 0; j < map.size(); ++j) {
      out.positions[j] = pred_global[f].positions[static_cast<size_t>(map[j])];
      out.rotations[j] = pred_global[f].rotations[static_cast<size_t>(map[j])];
    }
  }
  return track;
}

Track load_recording_prediction(const std::filesystem::path& path, const Motion& truth, const std::string& label) {
  protocol::PoseRecording rec;
  if (auto status = protocol::load_pose_recording(path, rec, /*allow_truncated_tail=*/true); !status) {
    throw RenderError("", status.error);
  }
  // Poses whose skeleton the recording holds, converted to the truth's joint order.
  struct Timed {
    std::int64_t t_ns;
    GlobalPose pose;
  };
  std::vector<Timed> poses;
  std::unordered_map<std::uint32_t, std::vector<int>> maps;
  int without_skeleton = 0;
  for (const protocol::PoseMessage& msg : rec.poses) {
    const protocol::SkeletonMessage* skel = protocol::find_skeleton(rec, msg.skeleton_id);
    if (skel == nullptr) {
      ++without_skeleton;
      continue;
    }
    auto it = maps.find(msg.skeleton_id);
    if (it == maps.end()) it = maps.emplace(msg.skeleton_id, map_joints(truth.skeleton, skel->names, path, "the truth")).first;
    const std::vector<int>& map = it->second;
    Timed timed{msg.t_ns, {}};
    timed.pose.positions.resize(map.size());
    timed.pose.rotations.resize(map.size());
    for (size_t j = 0; j < map.size(); ++j) {
      const protocol::JointState& js = msg.joints.at(static_cast<size_t>(map[j]));
      timed.pose.positions[j] = Vec3(js.position_m[0], js.position_m[1], js.position_m[2]);
      timed.pose.rotations[j] =
          Quat(js.rotation_xyzw[3], js.rotation_xyzw[0], js.rotation_xyzw[1], js.rotation_xyzw[2]).normalized();
    }
    poses.push_back(std::move(timed));
  }
  if (poses.empty()) {
    throw RenderError(
        path.string(),
        fmt::format("no pose with a known skeleton ({} poses, {} skeletons)", rec.poses.size(), rec.skeletons.size()),
        "record the stream for at least a second so the skeleton is included");
  }
  const int n = truth.frame_count();
  Track track{label, path, {}};
  track.frames.resize(static_cast<size_t>(n));
  if (static_cast<int>(poses.size()) == n) {
    for (int f = 0; f < n; ++f) track.frames[static_cast<size_t>(f)] = poses[static_cast<size_t>(f)].pose;
    return track;
  }
  const std::int64_t t0 = poses.front().t_ns;
  const double span_s = static_cast<double>(poses.back().t_ns - t0) * 1e-9;
  const double clip_s = (n - 1) * truth.frame_time_s;
  if (span_s + 0.5 * truth.frame_time_s < clip_s) {
    throw RenderError(
        path.string(),
        fmt::format("the recording spans {:.3f} s ({} poses{}), the ground truth clip {:.3f} s ({} frames)", span_s,
                    poses.size(),
                    without_skeleton ? fmt::format(", {} before any skeleton skipped", without_skeleton) : "", clip_s,
                    n),
        "record the whole clip");
  }
  size_t next = 0;
  for (int f = 0; f < n; ++f) {
    const double limit_s = (f + 0.5) * truth.frame_time_s;
    while (next + 1 < poses.size() && static_cast<double>(poses[next + 1].t_ns - t0) * 1e-9 <= limit_s) ++next;
    track.frames[static_cast<size_t>(f)] = poses[next].pose;
  }
  return track;
}

FrameErrors per_frame_errors(const JointSets& sets, const std::vector<GlobalPose>& prediction,
                             const std::vector<GlobalPose>& truth) {
  BODYD_REQUIRE(prediction.size() == truth.size(),
                fmt::format("per_frame_errors: {} predicted frames, {} true frames", prediction.size(), truth.size()));
  auto mean_cm = [](const std::vector<int>& joints, const GlobalPose& p, const GlobalPose& g) {
    double sum = 0.0;
    for (int j : joints) sum += (p.positions.at(static_cast<size_t>(j)) - g.positions.at(static_cast<size_t>(j))).norm();
    return joints.empty() ? std::nan("") : 100.0 * sum / static_cast<double>(joints.size());
  };
  FrameErrors out;
  out.all_cm.reserve(truth.size());
  out.lower_cm.reserve(truth.size());
  out.hands_cm.reserve(truth.size());
  for (size_t f = 0; f < truth.size(); ++f) {
    out.all_cm.push_back(mean_cm(sets.all, prediction[f], truth[f]));
    out.lower_cm.push_back(mean_cm(sets.lower, prediction[f], truth[f]));
    out.hands_cm.push_back(mean_cm(sets.hands, prediction[f], truth[f]));
  }
  return out;
}

Comparison make_comparison(const std::string& clip_name, const Motion& truth, std::vector<Track> predictions) {
  if (truth.frame_count() == 0) throw RenderError(clip_name, "the ground truth has no frames");
  Comparison cmp;
  cmp.clip_name = clip_name;
  cmp.skeleton = truth.skeleton;
  cmp.fps = truth.fps();
  cmp.truth = Track{"ground truth", clip_name, global_frames(truth)};
  JointSets sets;
  try {
    sets = joint_sets(truth.skeleton);
  } catch (const UserError& e) {
    throw RenderError(
        clip_name, e.problem().what,
        "the ground truth must use the bodyd skeleton (docs/conventions.md, \"Skeleton and joint sets\")");
  }
  MetricsAccumulator truth_only(truth.skeleton);
  truth_only.begin_clip(cmp.fps);
  for (const GlobalPose& g : cmp.truth.frames) truth_only.add_frame(g, g);
  (void)truth_only.end_clip();
  cmp.truth_quality = truth_only.last_clip_truth();
  for (Track& track : predictions) {
    if (track.frames.size() != cmp.truth.frames.size()) {
      throw RenderError(track.source.string(), fmt::format("{} frames, but the ground truth has {}",
                                                           track.frames.size(), cmp.truth.frames.size()));
    }
    for (const GlobalPose& p : track.frames) {
      if (p.positions.size() != static_cast<size_t>(truth.skeleton.size()) || p.rotations.size() != p.positions.size()) {
        throw RenderError(track.source.string(), fmt::format("poses have {} joints, the ground truth's skeleton {}",
                                                             p.positions.size(), truth.skeleton.size()));
      }
    }
    MethodResult result;
    result.errors = per_frame_errors(sets, track.frames, cmp.truth.frames);
    MetricsAccumulator acc(truth.skeleton);
    acc.begin_clip(cmp.fps);
    for (size_t f = 0; f < track.frames.size(); ++f) acc.add_frame(track.frames[f], cmp.truth.frames[f]);
    result.metrics = acc.end_clip();
    result.track = std::move(track);
    cmp.methods.push_back(std::move(result));
  }
  return cmp;
}

Comparison load_comparison(const std::filesystem::path& truth_path, const std::vector<PredictionSource>& predictions) {
  Motion truth;
  try {
    truth = read_bvh(truth_path);
  } catch (const BvhError& e) {
    throw RenderError(e.problem());
  }
  const std::string clip = truth_path.stem().string();
  std::vector<Track> tracks;
  for (const PredictionSource& src : predictions) {
    const std::string label = src.label.empty() ? default_label(src, clip) : src.label;
    tracks.push_back(src.kind == PredictionSource::Kind::kBvh ? load_bvh_prediction(src.path, truth, label)
                                                              : load_recording_prediction(src.path, truth, label));
  }
  Comparison cmp = make_comparison(clip, truth, std::move(tracks));
  cmp.truth.source = truth_path;
  return cmp;
}

}  // namespace bodyd::render
