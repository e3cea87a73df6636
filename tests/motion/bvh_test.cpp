#include "bodyd/motion/bvh.h"

#include "../test_paths.h"
#include "bodyd/test/files.h"

#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <sstream>

using namespace bodyd;

namespace {
using bodyd::test::read_file;

const char* kSmall =
    "HIERARCHY\nROOT hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    "  JOINT knee\n  {\n\tOFFSET 0 -40 0\n\tCHANNELS 3 Xrotation Yrotation Zrotation\n"
    "    End Site\n    {\n      OFFSET 0 -4.5e1 0\n    }\n  }\n}\n"
    "MOTION\nFrames: 2\nFrame Time: 0.0333333\n"
    "0 90 0 0 0 0 90 0 0\n"
    "1.5 90 0 90 0 0 0 0 0\n";

// Expects parsing `text` to throw BvhError whose message contains `line_tag` and `what`.
void expect_error(const std::string& text, const std::string& line_tag, const std::string& what) {
  try {
    (void)parse_bvh(text, "bad.bvh");
    FAIL() << "no error for: " << what;
  } catch (const BvhError& e) {
    std::string msg = e.what();
    EXPECT_NE(msg.find("bad.bvh:" + line_tag), std::string::npos) << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
  }
}

std::string replace(std::string s, const std::string& from, const std::string& to) {
  size_t p = s.find(from);
  EXPECT_NE(p, std::string::npos) << from;
  if (p != std::string::npos) s.replace(p, from.size(), to);
  return s;
}
}  // namespace

TEST(Bvh, ParsesSmallFileWithTabsEndSitesAndScientificNotation) {
  Motion m = parse_bvh(kSmall, "small.bvh");
  ASSERT_EQ(m.skeleton.size(), 2);
  EXPECT_EQ(m.frame_count(), 2);
  EXPECT_NEAR(m.fps(), 30.0, 1e-3);
  ASSERT_TRUE(m.skeleton.end_sites[1].has_value());
  EXPECT_NEAR(m.skeleton.end_sites[1]->y(), -0.45, 1e-12);
  // Frame 0: knee rotated 90 deg about X; the end site would point along -z... check FK of knee position.
  GlobalPose g = forward_kinematics(m.skeleton, m.frames[0]);
  EXPECT_NEAR((g.positions[0] - Vec3(0, 0.9, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((g.positions[1] - Vec3(0, 0.5, 0)).norm(), 0, 1e-12);
  // Frame 1: hips rotated 90 deg about Z, translated 1.5 cm in x: knee offset (0,-0.4,0) -> (0.4,0,0).
  g = forward_kinematics(m.skeleton, m.frames[1]);
  EXPECT_NEAR((g.positions[1] - Vec3(0.015 + 0.4, 0.9, 0)).norm(), 0, 1e-12);
}

TEST(Bvh, MalformedInputsNameTheLine) {
  const std::string ok = kSmall;
  expect_error(replace(ok, "MOTION", "MOTON"), "16", "expected 'MOTION'");
  expect_error(ok.substr(0, ok.find("MOTION")), "16", "missing MOTION");
  expect_error(replace(ok, "Frames: 2", "Frames: 3"), "20", "truncated");
  expect_error(replace(ok, "Frames: 2", "Frames: 1"), "20", "more frame lines");
  expect_error(replace(ok, "1.5 90 0 90 0 0 0 0 0", "1.5 90 0 90 0 0 0 0"), "20", "has 8 values");
  expect_error(replace(ok, "1.5 90 0 90 0 0 0 0 0", "1.5 90 0 90 0 0 0 0 0 7"), "20", "more than the 9 values");
  expect_error(replace(ok, "1.5 90", "1.5x 90"), "20", "not a number");
  expect_error(replace(ok, "1.5 90", "nan 90"), "20", "not finite");
  expect_error(replace(ok, "1.5 90", "inf 90"), "20", "not finite");
  expect_error(replace(ok, "Frame Time: 0.0333333", "Frame Time: 0"), "18", "frame time");
  expect_error(replace(ok, "Frame Time: 0.0333333", "Frame Time: 1e9"), "18", "frame time");
  expect_error(replace(ok, "CHANNELS 3 Xrotation", "CHANNELS 4 Xrotation"), "10", "not a channel name");
  expect_error(replace(ok, "CHANNELS 3", "CHANNELS 7"), "9", "CHANNELS count");
  expect_error(replace(ok, "Frames: 2", "Frames: -2"), "17", "frame count");
  expect_error(replace(ok, "OFFSET 0 -40 0", "OFFSET 0 -40"), "9", "OFFSET value");
  expect_error(ok.substr(0, 60), "", "unexpected end of file");
  expect_error("", "1", "expected 'HIERARCHY'");
}

// Issue 11: a finite but absurd value (1e300) loaded, and forward kinematics then gave inf/NaN
// to every metric and 9e292 to simulated trackers. Lengths (OFFSET, End Site, position
// channels) must lie within +-limits::kMaxAbsPositionM metres after the unit conversion.
TEST(Bvh, RejectsFiniteAbsurdValuesWithTheLine) {
  const std::string ok = kSmall;
  expect_error(replace(ok, "1.5 90", "1e300 90"), "20", "frame 1: joint 'hips' Xposition 1e+300 is 1e+298 m, outside");
  expect_error(replace(ok, "1.5 90", "1e300 90"), "20", "is the file in centimetres?");
  expect_error(replace(ok, "1.5 90", "-10000.5 90"), "20", "outside the plausible range +-100 m");
  expect_error(replace(ok, "OFFSET 0 -40 0", "OFFSET 0 -40 1e300"), "8", "OFFSET value 1e+300 is 1e+298 m");
  expect_error(replace(ok, "OFFSET 0 -4.5e1 0", "OFFSET 0 -4.5e9 0"), "12", "End Site OFFSET value -4500000000 is -4.5e+07 m");
  expect_error(replace(ok, "1.5 90 0 90", "1.5 90 0 1e6"), "20", "Zrotation 1000000 degrees is outside");
  // The edges are inside: 10000 cm is 100 m.
  const Motion edge = parse_bvh(replace(replace(ok, "1.5 90", "-10000 10000"), "OFFSET 0 -40 0", "OFFSET 0 -40 10000"),
                                "edge.bvh");
  EXPECT_DOUBLE_EQ(edge.frames[1].local_translations[0].x(), -100.0);
  EXPECT_DOUBLE_EQ(edge.skeleton.offsets[1].z(), 100.0);
  // A unit that turns sane numbers into absurd ones is refused too.
  EXPECT_THROW((void)parse_bvh(ok, "units.bvh", BvhReadOptions{1e9}), BvhError);
  EXPECT_THROW((void)parse_bvh(ok, "units.bvh", BvhReadOptions{-0.01}), BvhError);
}

// Messages that quote the file escape control and non-ASCII bytes, so a file cannot send
// terminal escape sequences through an error; joint names with control bytes are refused.
TEST(Bvh, MessagesEscapeBytesFromTheFile) {
  const std::string ok = kSmall;
  auto message = [](const std::string& text) -> std::string {
    try {
      (void)parse_bvh(text, "esc.bvh");
    } catch (const BvhError& e) {
      return e.what();
    }
    ADD_FAILURE() << "no error";
    return {};
  };
  const std::string raw = "\x1b]0;owned\x07\x1b[2J";
  for (const std::string& bad : {replace(ok, "MOTION", "M" + std::string("\x1b[2J")),
                                 replace(ok, "JOINT knee", "JOINT kn\x1b[31mee"),
                                 replace(ok, "1.5 90", "1.5\x1b[2J 90"),
                                 replace(ok, "Xrotation Yrotation Zrotation\n", "Xrotation Yrotation \x9b" "31m\n"),
                                 replace(ok, "Frame Time: 0.0333333", "Frame Time: 0.0333333 \x1b[2J"),
                                 replace(ok, "OFFSET 0 -40 0", "OFFSET 0 -40 0 " + raw)}) {
    const std::string msg = message(bad);
    SCOPED_TRACE(msg);
    EXPECT_EQ(msg.find('\x1b'), std::string::npos);
    EXPECT_EQ(msg.find('\x9b'), std::string::npos);
    EXPECT_EQ(msg.find('\x07'), std::string::npos);
    EXPECT_TRUE(msg.find("\\x1b") != std::string::npos || msg.find("\\x9b") != std::string::npos);
  }
  EXPECT_NE(message(replace(ok, "JOINT knee", "JOINT kn\x1b[31mee")).find("holds a control character"),
            std::string::npos);
}

TEST(Bvh, NeverCrashesOnTruncations) {
  // Every prefix of a valid file is either the whole motion (only the final newline is
  // missing) or a clean BvhError that names the file and says what is wrong.
  const std::string ok = kSmall;
  const Motion full = parse_bvh(ok, "full.bvh");
  int accepted = 0;
  for (size_t n = 0; n < ok.size(); ++n) {
    SCOPED_TRACE(n);
    try {
      const Motion m = parse_bvh(ok.substr(0, n), "prefix.bvh");
      ++accepted;
      ASSERT_EQ(m.skeleton.size(), full.skeleton.size());
      for (int j = 0; j < full.skeleton.size(); ++j) {
        const size_t i = static_cast<size_t>(j);
        EXPECT_EQ(m.skeleton.names[i], full.skeleton.names[i]);
        EXPECT_EQ(m.skeleton.parents[i], full.skeleton.parents[i]);
        EXPECT_EQ(m.skeleton.offsets[i], full.skeleton.offsets[i]);
        EXPECT_EQ(m.skeleton.end_sites[i], full.skeleton.end_sites[i]);
      }
      EXPECT_EQ(m.frame_time_s, full.frame_time_s);
      ASSERT_EQ(m.frame_count(), full.frame_count());
      for (size_t f = 0; f < full.frames.size(); ++f) {
        const GlobalPose a = forward_kinematics(full.skeleton, full.frames[f]);
        const GlobalPose b = forward_kinematics(m.skeleton, m.frames[f]);
        for (size_t j = 0; j < a.positions.size(); ++j) EXPECT_EQ(a.positions[j], b.positions[j]) << f << " " << j;
      }
    } catch (const BvhError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind("prefix.bvh", 0), 0u) << msg;
      EXPECT_GT(msg.size(), std::string("prefix.bvh: ").size()) << msg;
    }
  }
  // The cut that drops only the last newline is accepted; every shorter one loses data.
  EXPECT_EQ(accepted, 1);
}

TEST(Bvh, WriteReadRoundTrip) {
  Motion m = read_bvh(test::fixtures() / "walk_60.bvh");
  std::string text = format_bvh(m);
  Motion back = parse_bvh(text, "roundtrip.bvh");
  ASSERT_EQ(back.skeleton.size(), m.skeleton.size());
  ASSERT_EQ(back.frame_count(), m.frame_count());
  EXPECT_NEAR(back.frame_time_s, m.frame_time_s, 1e-9);
  for (int f = 0; f < m.frame_count(); f += 7) {
    GlobalPose a = forward_kinematics(m.skeleton, m.frames[static_cast<size_t>(f)]);
    GlobalPose b = forward_kinematics(back.skeleton, back.frames[static_cast<size_t>(f)]);
    for (int j = 0; j < m.skeleton.size(); ++j) {
      EXPECT_LT((a.positions[static_cast<size_t>(j)] - b.positions[static_cast<size_t>(j)]).norm(), 1e-5);
      EXPECT_LT(geodesic_angle(a.rotations[static_cast<size_t>(j)], b.rotations[static_cast<size_t>(j)]), 1e-5);
    }
  }
}

TEST(Bvh, FixtureForwardKinematicsIsAStandingPerson) {
  Motion m = read_bvh(test::fixtures() / "walk_60.bvh");
  ASSERT_EQ(m.skeleton.size(), 22);
  const int head = m.skeleton.find("Head"), toe_l = m.skeleton.find("Toes_L"), toe_r = m.skeleton.find("Toes_R");
  const int hips = m.skeleton.find("Hips");
  ASSERT_GE(head, 0);
  ASSERT_GE(toe_l, 0);
  GlobalPose g = forward_kinematics(m.skeleton, m.frames[0]);
  const double head_y = g.positions[static_cast<size_t>(head)].y();
  EXPECT_GT(head_y, 1.35);
  EXPECT_LT(head_y, 1.80);
  EXPECT_LT(std::min(g.positions[static_cast<size_t>(toe_l)].y(), g.positions[static_cast<size_t>(toe_r)].y()), 0.08);
  EXPECT_GT(g.positions[static_cast<size_t>(hips)].y(), 0.8);
  EXPECT_LT(g.positions[static_cast<size_t>(hips)].y(), 1.1);
}

TEST(Bvh, EveryBandaiFileLoads) {
  if (!test::have_bandai()) GTEST_SKIP() << "../shared/data/bandai-namco not present";
  int files = 0;
  for (const char* split : {"train.txt", "val.txt"}) {
    std::ifstream list(test::bandai() / "splits" / split);
    std::string rel;
    while (std::getline(list, rel)) {
      if (rel.empty()) continue;
      const auto path = test::bandai() / rel;
      Motion m = read_bvh(path);
      // Frame count equals the file's own "Frames:" line.
      std::smatch match;
      std::string text = read_file(path);
      std::regex re("Frames:\\s*(\\d+)");
      ASSERT_TRUE(std::regex_search(text, match, re)) << rel;
      EXPECT_EQ(m.frame_count(), std::stoi(match[1])) << rel;
      EXPECT_EQ(m.skeleton.size(), 22) << rel;
      ++files;
    }
  }
  EXPECT_EQ(files, 888);
}
