// bodyd_render: per-frame errors, loading and checking predictions (BVH and pose recordings),
// the pictures (sizes, determinism, APNG structure) and bodyd-render's command line.
#include "bodyd/render/apng.h"
#include "bodyd/render/comparison.h"
#include "bodyd/render/draw.h"

#include "bodyd/protocol/recording.h"
#include "../test_paths.h"
#include "bodyd/test/files.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using namespace bodyd;
using namespace bodyd::render;

namespace {

using bodyd::test::TempDir;

Motion walk() { return read_bvh(test::fixtures() / "walk_60.bvh"); }

// The message of the RenderError that `load` throws; a test failure (and "") when it throws none.
template <class Load>
std::string render_error(Load&& load) {
  try {
    load();
  } catch (const RenderError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no error";
  return "";
}

// The clip moved by `offset_m` in the floor plane (root translation), so every joint is off by |offset|.
Motion shifted(const Motion& m, const Vec3& offset_m) {
  Motion out = m;
  for (Pose& p : out.frames) p.local_translations[0] += offset_m;
  return out;
}

using bodyd::test::read_file;
using bodyd::test::read_file_bytes;

// `m` cut to its first `frames` frames, written as tmp/short.bvh.
fs::path write_short_clip(const TempDir& tmp, const Motion& m, std::size_t frames) {
  Motion short_clip = m;
  short_clip.frames.resize(frames);
  write_bvh(tmp.path / "short.bvh", short_clip);
  return tmp.path / "short.bvh";
}

ImageSize png_size(const std::vector<std::uint8_t>& png) {
  const auto chunks = parse_png_chunks(png);
  const auto& d = chunks.front().data;
  auto u32 = [&](size_t at) {
    return static_cast<int>((std::uint32_t{d[at]} << 24) | (std::uint32_t{d[at + 1]} << 16) | (std::uint32_t{d[at + 2]} << 8) |
                            std::uint32_t{d[at + 3]});
  };
  return {u32(0), u32(4)};
}

struct RunResult {
  int exit_code;
  std::string out, err;
};
RunResult run_render(const std::string& args, const TempDir& tmp) {
  const fs::path out = tmp.path / "stdout.txt", err = tmp.path / "stderr.txt";
  const std::string cmd = (test::bin_dir() / "bodyd-render").string() + " " + args + " >" + out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, read_file(out), read_file(err)};
}

// A pose recording of `m` as bodyd-record would write it: the skeleton, then `per_frame` poses per
// clip frame at per_frame * fps Hz, pose i showing frame (i + per_frame / 2) / per_frame (rounded down,
// clamped): the pose the resampling picks for frame f, 3f + 1 at per_frame 3, shows frame f.
void write_recording(const Motion& m, int per_frame, int poses, const fs::path& path) {
  protocol::SkeletonMessage skel;
  for (int j = 0; j < m.skeleton.size(); ++j) {
    skel.names.push_back(m.skeleton.names[static_cast<size_t>(j)]);
    skel.parents.push_back(static_cast<std::int16_t>(m.skeleton.parents[static_cast<size_t>(j)]));
    const Vec3& o = m.skeleton.offsets[static_cast<size_t>(j)];
    skel.offsets_m.push_back({static_cast<float>(o.x()), static_cast<float>(o.y()), static_cast<float>(o.z())});
  }
  skel.skeleton_id = protocol::skeleton_id_of(skel);
  std::vector<std::uint8_t> file, frame;
  protocol::append_recording_header(0, file);
  ASSERT_TRUE(protocol::encode_skeleton(skel, frame).ok());
  ASSERT_TRUE(protocol::append_recording_frame(0, protocol::kSkeletonTopic, frame, file).ok());
  const double dt_ns = 1e9 / (m.fps() * per_frame);
  for (int i = 0; i < poses; ++i) {
    const int f = std::min((i + per_frame / 2) / per_frame, m.frame_count() - 1);
    const GlobalPose g = forward_kinematics(m.skeleton, m.frames[static_cast<size_t>(f)]);
    protocol::PoseMessage pose;
    pose.seq = static_cast<std::uint64_t>(i);
    pose.t_ns = 5'000'000'000 + std::llround(i * dt_ns);
    pose.publish_t_ns = pose.t_ns;
    pose.skeleton_id = skel.skeleton_id;
    for (size_t j = 0; j < g.positions.size(); ++j) {
      protocol::JointState js;
      js.position_m = {static_cast<float>(g.positions[j].x()), static_cast<float>(g.positions[j].y()),
                       static_cast<float>(g.positions[j].z())};
      const Quat& q = g.rotations[j];
      js.rotation_xyzw = {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                          static_cast<float>(q.w())};
      pose.joints.push_back(js);
    }
    ASSERT_TRUE(protocol::encode_pose(pose, frame).ok());
    ASSERT_TRUE(protocol::append_recording_frame(pose.t_ns, protocol::kPoseTopic, frame, file).ok());
  }
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(file.data()),
                                              static_cast<std::streamsize>(file.size()));
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

}  // namespace

TEST(RenderErrors, TruthAgainstItselfIsFlatZero) {
  const Motion m = walk();
  const Comparison cmp = make_comparison("walk_60", m, {Track{"self", "walk_60.bvh", global_frames(m)}});
  ASSERT_EQ(cmp.methods.size(), 1u);
  const FrameErrors& e = cmp.methods[0].errors;
  ASSERT_EQ(e.all_cm.size(), 60u);
  for (size_t f = 0; f < 60; ++f) {
    EXPECT_EQ(e.all_cm[f], 0.0) << f;
    EXPECT_EQ(e.lower_cm[f], 0.0) << f;
    EXPECT_EQ(e.hands_cm[f], 0.0) << f;
  }
  EXPECT_EQ(cmp.methods[0].metrics.mpjpe_cm, 0.0);
}

TEST(RenderErrors, ShiftedClipIsOffByTheShiftEverywhere) {
  // Moving the whole body 3 cm along x and 4 cm along z puts every joint 5 cm off (golden by hand).
  const Motion m = walk();
  const Motion s = shifted(m, Vec3(0.03, 0.0, 0.04));
  const Comparison cmp = make_comparison("walk_60", m, {Track{"shifted", "s.bvh", global_frames(s)}});
  const FrameErrors& e = cmp.methods[0].errors;
  for (size_t f = 0; f < e.all_cm.size(); ++f) {
    EXPECT_NEAR(e.all_cm[f], 5.0, 1e-9);
    EXPECT_NEAR(e.lower_cm[f], 5.0, 1e-9);
    EXPECT_NEAR(e.hands_cm[f], 5.0, 1e-9);
  }
}

TEST(RenderErrors, PerFrameMeansAgreeWithTheMetrics) {
  // A perturbation that varies by frame and joint: the means of the per-frame errors must equal
  // inference's mpjpe_cm, lower_pe_cm and hand_pe_cm (all frames have equal weight).
  const Motion m = walk();
  Motion p = m;
  for (size_t f = 0; f < p.frames.size(); ++f) {
    for (size_t j = 1; j < p.frames[f].local_rotations.size(); ++j) {
      p.frames[f].local_rotations[j] =
          p.frames[f].local_rotations[j] * quat_from_axis_angle(Vec3(0.01 * static_cast<double>(f % 7), 0.02 * static_cast<double>(j % 3), 0.0));
    }
  }
  const Comparison cmp = make_comparison("walk_60", m, {Track{"p", "p.bvh", global_frames(p)}});
  const MethodResult& r = cmp.methods[0];
  EXPECT_GT(r.metrics.mpjpe_cm, 1.0);
  EXPECT_NEAR(mean(r.errors.all_cm), r.metrics.mpjpe_cm, 1e-9);
  EXPECT_NEAR(mean(r.errors.lower_cm), r.metrics.lower_pe_cm, 1e-9);
  EXPECT_NEAR(mean(r.errors.hands_cm), r.metrics.hand_pe_cm, 1e-9);
}

TEST(RenderLoad, DefaultLabelsFollowBodydEvalNames) {
  using K = PredictionSource::Kind;
  EXPECT_EQ(default_label({K::kBvh, "out/walk.pred.bvh", {}}, "walk"), "diffusion");
  EXPECT_EQ(default_label({K::kBvh, "out/walk.ik.pred.bvh", {}}, "walk"), "ik");
  EXPECT_EQ(default_label({K::kBvh, "other.bvh", {}}, "walk"), "other");
  EXPECT_EQ(default_label({K::kRecording, "walk.bdrec", {}}, "walk"), "recording");
}

TEST(RenderLoad, WrongFrameCountIsAClearError) {
  TempDir tmp;
  const Motion m = walk();
  const fs::path short_bvh = write_short_clip(tmp, m, 50);
  const std::string e = render_error([&] { (void)load_bvh_prediction(short_bvh, m, "x"); });
  EXPECT_NE(e.find("short.bvh: 50 frames, but the ground truth has 60"), std::string::npos) << e;
}

TEST(RenderLoad, OtherSkeletonNamesTheMissingJoint) {
  TempDir tmp;
  Motion m = walk();
  Motion other = m;
  other.skeleton.names[static_cast<size_t>(other.skeleton.find("Hand_L"))] = "LeftHand";
  write_bvh(tmp.path / "other.bvh", other);
  const std::string e = render_error([&] { (void)load_bvh_prediction(tmp.path / "other.bvh", m, "x"); });
  EXPECT_NE(e.find("lacks joints of the ground truth"), std::string::npos) << e;
  EXPECT_NE(e.find("Hand_L"), std::string::npos) << e;
}

TEST(RenderLoad, RecordingOnePosePerFrameAndResampled) {
  TempDir tmp;
  const Motion m = walk();
  for (int per_frame : {1, 3}) {
    const fs::path path = tmp.path / ("rec" + std::to_string(per_frame) + ".bdrec");
    write_recording(m, per_frame, per_frame == 1 ? 60 : 180, path);
    const Track t = load_recording_prediction(path, m, "rec");
    const Comparison cmp = make_comparison("walk_60", m, {t});
    // float32 positions on the wire: errors below 0.01 mm.
    for (double v : cmp.methods[0].errors.all_cm) EXPECT_LT(v, 1e-3) << "per_frame " << per_frame;
  }
}

TEST(RenderLoad, RecordingShorterThanTheClipIsAnError) {
  TempDir tmp;
  const Motion m = walk();
  write_recording(m, 3, 90, tmp.path / "half.bdrec");
  const std::string e = render_error([&] { (void)load_recording_prediction(tmp.path / "half.bdrec", m, "rec"); });
  EXPECT_NE(e.find("record the whole clip"), std::string::npos) << e;
}

TEST(RenderPictures, SizesAndDeterminism) {
  const Motion m = walk();
  const Motion s = shifted(m, Vec3(0.05, 0.0, 0.0));
  const Comparison cmp = make_comparison("walk_60", m, {Track{"shifted", "s.bvh", global_frames(s)}});
  SheetOptions opt;
  opt.every = 10;
  opt.columns = 4;
  EXPECT_EQ(sheet_frames(60, opt), (std::vector<int>{0, 10, 20, 30, 40, 50}));
  const auto sheet1 = contact_sheet_png(cmp, opt);
  const auto sheet2 = contact_sheet_png(cmp, opt);
  EXPECT_EQ(sheet1, sheet2);
  const ImageSize expected = contact_sheet_size(cmp, opt);
  EXPECT_EQ(png_size(sheet1).width, expected.width);
  EXPECT_EQ(png_size(sheet1).height, expected.height);
  EXPECT_EQ(expected.width, 20 + 4 * 300);  // 4 columns
  opt.joint_names = true;
  EXPECT_NE(contact_sheet_png(cmp, opt), sheet1);  // names are drawn
  const auto plot = error_plot_png(cmp);
  EXPECT_EQ(plot, error_plot_png(cmp));
  EXPECT_EQ(png_size(plot).width, kErrorPlotSize.width);
  EXPECT_EQ(png_size(plot).height, kErrorPlotSize.height);
}

TEST(RenderApng, StructureOfTheAnimation) {
  const Motion m = walk();
  const Comparison cmp = make_comparison("walk_60", m, {Track{"self", "s.bvh", global_frames(m)}});
  const auto apng = animation_apng(cmp, {20});  // frames 0, 20, 40
  const auto chunks = parse_png_chunks(apng);
  ASSERT_GE(chunks.size(), 4u);
  EXPECT_EQ(chunks[0].type, "IHDR");
  EXPECT_EQ(chunks[1].type, "acTL");
  EXPECT_EQ(chunks[1].data, (std::vector<std::uint8_t>{0, 0, 0, 3, 0, 0, 0, 0}));  // 3 frames, loop forever
  int fctl = 0, idat = 0, fdat = 0;
  std::uint32_t expected_seq = 0;
  for (const auto& c : chunks) {
    auto seq = [&] {
      return (std::uint32_t{c.data[0]} << 24) | (std::uint32_t{c.data[1]} << 16) | (std::uint32_t{c.data[2]} << 8) | c.data[3];
    };
    if (c.type == "fcTL") {
      ++fctl;
      EXPECT_EQ(seq(), expected_seq++);
      EXPECT_EQ(c.data[20], 2);  // delay 667/1000 s = 20 frames at 30 fps
      EXPECT_EQ(c.data[21], 0x9B);
    } else if (c.type == "fdAT") {
      ++fdat;
      EXPECT_EQ(seq(), expected_seq++);
    } else if (c.type == "IDAT") {
      ++idat;
      EXPECT_EQ(fctl, 1) << "IDAT belongs to the first frame";
    }
  }
  EXPECT_EQ(fctl, 3);
  EXPECT_GE(idat, 1);
  EXPECT_GE(fdat, 2);
  EXPECT_EQ(chunks.back().type, "IEND");
  const ImageSize size = png_size(apng);
  EXPECT_EQ(size.width, kAnimationFrameSize.width);
  EXPECT_EQ(size.height, kAnimationFrameSize.height);
}

TEST(RenderApng, RejectsMismatchedAndCorruptFrames) {
  const Motion m = walk();
  const Comparison cmp = make_comparison("walk_60", m, {Track{"self", "s.bvh", global_frames(m)}});
  const auto frame = animation_frame_png(cmp, 0);
  const auto plot = error_plot_png(cmp);
  EXPECT_THROW((void)assemble_apng({frame, plot}, 1, 30), RenderError);
  auto corrupt = frame;
  corrupt[40] ^= 0xFF;
  EXPECT_THROW((void)assemble_apng({frame, corrupt}, 1, 30), RenderError);
  EXPECT_THROW((void)assemble_apng({}, 1, 30), RenderError);
}

TEST(RenderTool, WritesDeterministicPictures) {
  TempDir tmp;
  const Motion m = walk();
  write_bvh(tmp.path / "walk_60.ik.pred.bvh", shifted(m, Vec3(0.0, 0.0, 0.06)));
  write_bvh(tmp.path / "walk_60.pred.bvh", shifted(m, Vec3(0.02, 0.0, 0.0)));
  const std::string args = "--truth " + (test::fixtures() / "walk_60.bvh").string() + " --pred " +
                           (tmp.path / "walk_60.pred.bvh").string() + " --pred " +
                           (tmp.path / "walk_60.ik.pred.bvh").string() + " --every 10 --apng --anim-every 15";
  RunResult r = run_render(args + " --out " + (tmp.path / "a").string(), tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("diffusion: mpjpe_cm 2.00"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ik: mpjpe_cm 6.00"), std::string::npos) << r.out;
  r = run_render(args + " --out " + (tmp.path / "b").string(), tmp);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* name : {"walk_60.contact_sheet.png", "walk_60.error_plot.png", "walk_60.anim.png"}) {
    const auto a = read_file_bytes(tmp.path / "a" / name);
    ASSERT_GT(a.size(), 1000u) << name;
    EXPECT_EQ(a, read_file_bytes(tmp.path / "b" / name)) << name << " differs between two runs";
  }
  const ImageSize sheet = png_size(read_file_bytes(tmp.path / "a" / "walk_60.contact_sheet.png"));
  EXPECT_EQ(sheet.width, 20 + 6 * 300);  // 6 frames (every 10 of 60) in one row of 6
}

TEST(RenderTool, MismatchedInputsFailWithTheReason) {
  TempDir tmp;
  const fs::path short_bvh = write_short_clip(tmp, walk(), 30);
  const std::string truth = (test::fixtures() / "walk_60.bvh").string();
  RunResult r = run_render("--truth " + truth + " --pred " + short_bvh.string() + " --out " +
                               (tmp.path / "o").string(),
                           tmp);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("short.bvh: 30 frames, but the ground truth has 60"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp.path / "o" / "walk_60.contact_sheet.png"));
  r = run_render("--truth " + truth + " --out " + (tmp.path / "o").string(), tmp);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("at least one --pred or --recording"), std::string::npos) << r.err;
  r = run_render("--truth " + truth + " --pred " + truth + " --recording " + (test::fixtures() / "bow_30.bvh").string() +
                     " --out " + (tmp.path / "o").string(),
                 tmp);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bow_30.bvh"), std::string::npos) << r.err;
}
