// bodyd-bvh and bodyd-sim run as processes, as a user runs them.
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/tracker_log.h"
#include "bodyd/simulators/tracker_sim.h"

#include "../test_paths.h"
#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/tracker_sample.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <sys/wait.h>
#include <unistd.h>

using namespace bodyd;
namespace fs = std::filesystem;

namespace {

using bodyd::test::read_file;
using bodyd::test::same_samples;

struct ProcessResult {
  int exit_code = -1;
  std::string out, err;
};

class ToolsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("bodyd-tools-test-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  // Runs bin/<tool> with the arguments as its own argv (posix_spawn, no shell: a single shell
  // string holding every data-set path would pass Linux's 128 KiB limit on one argument);
  // captures exit code, stdout and stderr.
  ProcessResult run(const std::string& tool, const std::vector<std::string>& args) {
    std::vector<std::string> argv{(test::bin_dir() / tool).string()};
    argv.insert(argv.end(), args.begin(), args.end());
    const test::RunResult rr =
        test::run(argv, {.stdout_path = dir_ / "stdout.txt", .stderr_path = dir_ / "stderr.txt"}, 300000);
    ProcessResult r;
    r.exit_code = rr.exit_code;
    r.out = rr.out;
    r.err = rr.err;
    return r;
  }
  fs::path dir_;
};

const std::string kWalk = (test::fixtures() / "walk_60.bvh").string();
const std::string kBow = (test::fixtures() / "bow_30.bvh").string();

}  // namespace

TEST_F(ToolsTest, BvhPrintsFramesRateAndJoints) {
  const ProcessResult r = run("bodyd-bvh", {kWalk, kBow});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  const std::regex line(R"((.*): (\d+) frames, ([0-9.]+) fps, (\d+) joints)");
  std::istringstream in(r.out);
  std::string l;
  std::vector<std::string> lines;
  while (std::getline(in, l)) lines.push_back(l);
  ASSERT_EQ(lines.size(), 2u) << r.out;
  std::smatch a, b;
  ASSERT_TRUE(std::regex_match(lines[0], a, line)) << lines[0];
  ASSERT_TRUE(std::regex_match(lines[1], b, line)) << lines[1];
  EXPECT_EQ(a[1], kWalk);
  EXPECT_EQ(a[2], "60");
  EXPECT_NEAR(std::stod(a[3]), 30.0, 0.01);
  EXPECT_EQ(a[4], "22");
  EXPECT_EQ(b[1], kBow);
  EXPECT_EQ(b[2], "30");
}

TEST_F(ToolsTest, BvhJson) {
  const ProcessResult r = run("bodyd-bvh", {"--json", kWalk, kBow});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_TRUE(j.is_array());
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[0]["path"], kWalk);
  EXPECT_EQ(j[0]["frames"], 60);
  EXPECT_NEAR(j[0]["fps"].get<double>(), 30.0, 0.01);
  EXPECT_EQ(j[0]["joints"], 22);
  EXPECT_EQ(j[1]["path"], kBow);
  EXPECT_EQ(j[1]["frames"], 30);
}

TEST_F(ToolsTest, BvhReportsADamagedFileWithItsLineAndStillTheGoodOnes) {
  // Line 140 of the fixture is frame 5; put a word in the middle of it.
  std::string text = read_file(kWalk);
  size_t pos = 0;
  for (int line = 1; line < 140; ++line) pos = text.find('\n', pos) + 1;
  const size_t space = text.find(' ', pos + 10);
  text.replace(space, 1, " abc ");
  const fs::path bad = dir_ / "damaged.bvh";
  std::ofstream(bad, std::ios::binary) << text;

  const ProcessResult r = run("bodyd-bvh", {kWalk, bad.string(), kBow});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(bad.string() + ":140:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("'abc' is not a number"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find(kWalk + ": 60 frames"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(kBow + ": 30 frames"), std::string::npos) << r.out;

  const ProcessResult j = run("bodyd-bvh", {"--json", bad.string(), kWalk});
  EXPECT_EQ(j.exit_code, 1);
  const auto arr = nlohmann::json::parse(j.out);
  ASSERT_EQ(arr.size(), 1u);
  EXPECT_EQ(arr[0]["path"], kWalk);
  EXPECT_NE(j.err.find(":140:"), std::string::npos) << j.err;

  const ProcessResult missing = run("bodyd-bvh", {(dir_ / "nope.bvh").string()});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find("cannot open"), std::string::npos) << missing.err;
  EXPECT_EQ(run("bodyd-bvh", {}).exit_code, 2);  // no files: usage error
  const ProcessResult dir = run("bodyd-bvh", {dir_.string()});
  EXPECT_EQ(dir.exit_code, 1);
  EXPECT_NE(dir.err.find("is a directory"), std::string::npos) << dir.err;
}

// Issue 11: a clip with a finite absurd value (1e300) loaded, and bodyd-sim wrote 9e292 positions.
// Now bodyd-bvh and bodyd-sim refuse it with the file and line, and write nothing.
TEST_F(ToolsTest, AbsurdBvhValuesAreRefusedWithTheLine) {
  std::string text = read_file(kWalk);
  size_t pos = 0;
  for (int line = 1; line < 140; ++line) pos = text.find('\n', pos) + 1;
  text.replace(pos, text.find(' ', pos) - pos, "1e300");  // frame 5's root Xposition
  const fs::path bad = dir_ / "absurd.bvh";
  std::ofstream(bad, std::ios::binary) << text;

  const ProcessResult b = run("bodyd-bvh", {bad.string()});
  EXPECT_EQ(b.exit_code, 1);
  EXPECT_NE(b.err.find(bad.string() + ":140: frame 5: joint 'joint_Root' Xposition 1e+300"), std::string::npos)
      << b.err;
  const ProcessResult s = run("bodyd-sim", {"--bvh", bad.string(), "--out", (dir_ / "t.csv").string()});
  EXPECT_EQ(s.exit_code, 1);
  EXPECT_NE(s.err.find(bad.string() + ":140:"), std::string::npos) << s.err;
  EXPECT_NE(s.err.find("outside the plausible range"), std::string::npos) << s.err;
  EXPECT_FALSE(fs::exists(dir_ / "t.csv"));
}

// bodyd-bvh never passes raw control bytes from a file (or a file name) to the terminal.
TEST_F(ToolsTest, BvhEscapesControlBytesFromTheFile) {
  std::string text = read_file(kWalk);
  const size_t motion = text.find("MOTION");
  ASSERT_NE(motion, std::string::npos);
  text.replace(motion, 6, "\x1b]0;owned\x07\x1b[2J\x9b");
  const fs::path bad = dir_ / "esc\x1b[31m.bvh";
  std::ofstream(bad, std::ios::binary) << text;
  for (const auto& args : {std::vector<std::string>{bad.string()}, std::vector<std::string>{"--json", bad.string()}}) {
    const ProcessResult r = run("bodyd-bvh", args);
    EXPECT_EQ(r.exit_code, 1);
    for (char c : {'\x1b', '\x07', '\x9b'}) {
      EXPECT_EQ(r.err.find(c), std::string::npos) << r.err;
      EXPECT_EQ(r.out.find(c), std::string::npos) << r.out;
    }
    EXPECT_NE(r.err.find("found '\\x1b]0;owned\\x07\\x1b[2J\\x9b'"), std::string::npos) << r.err;
  }
  // A good file whose name holds an escape byte: the name is escaped on stdout too.
  const fs::path good = dir_ / "good\x1b[2J.bvh";
  fs::copy_file(kWalk, good);
  const ProcessResult g = run("bodyd-bvh", {good.string()});
  EXPECT_EQ(g.exit_code, 0) << g.err;
  EXPECT_EQ(g.out.find('\x1b'), std::string::npos) << g.out;
  EXPECT_NE(g.out.find("good\\x1b[2J.bvh: 60 frames"), std::string::npos) << g.out;
}

// Every file of the shared data set: frames agree with each file's own "Frames:" line.
TEST_F(ToolsTest, BvhOnEveryBandaiFile) {
  if (!test::have_bandai()) GTEST_SKIP() << "no " << test::bandai();
  std::vector<std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(test::bandai()))
    if (e.is_regular_file() && e.path().extension() == ".bvh") files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  ASSERT_GT(files.size(), 100u);
  std::vector<std::string> args{"--json"};
  args.insert(args.end(), files.begin(), files.end());
  const ProcessResult r = run("bodyd-bvh", args);
  ASSERT_EQ(r.exit_code, 0) << r.err.substr(0, 2000);
  const auto arr = nlohmann::json::parse(r.out);
  ASSERT_EQ(arr.size(), files.size());
  const std::regex frames_line(R"(Frames:\s*(\d+))");
  for (size_t i = 0; i < files.size(); ++i) {
    SCOPED_TRACE(files[i]);
    ASSERT_EQ(arr[i]["path"], files[i]);
    const std::string text = read_file(files[i]);
    const size_t at = text.find("Frames:");
    ASSERT_NE(at, std::string::npos);
    std::smatch m;
    const std::string head = text.substr(at, 40);
    ASSERT_TRUE(std::regex_search(head, m, frames_line));
    EXPECT_EQ(arr[i]["frames"].get<int>(), std::stoi(m[1]));
    EXPECT_EQ(arr[i]["joints"].get<int>(), 22);
    EXPECT_NEAR(arr[i]["fps"].get<double>(), 30.0, 0.01);
  }
}

// --trackers (issue 44): body trackers' rows, rotation-only ones without a position, the set in
// the metadata; a set without the head is a usage error naming what is accepted.
TEST_F(ToolsTest, SimTrackersSimulatesBodyTrackers) {
  const fs::path out = dir_ / "body.csv";
  const ProcessResult r = run("bodyd-sim", {"--bvh", kWalk, "--out", out.string(), "--trackers", "head,hands,hips:rot,feet"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const TrackerLog log = read_tracker_log(out);
  std::map<Role, int> n;
  for (const TrackerSample& s : log.samples) {
    ++n[s.role];
    if (s.role == Role::Hips) {
      EXPECT_FALSE(s.has_position);
    }
    if (s.role == Role::LeftFoot) {
      EXPECT_TRUE(s.has_position);
    }
  }
  EXPECT_EQ(n.size(), 6u);
  EXPECT_GT(n[Role::Hips], 100);
  EXPECT_EQ(n[Role::Chest], 0);
  EXPECT_NE(read_file(out).find("# trackers: head,left_hand,right_hand,hips:rot,left_foot,right_foot"), std::string::npos);
  const ProcessResult bad = run("bodyd-sim", {"--bvh", kWalk, "--out", (dir_ / "x.csv").string(), "--trackers", "hands,tail"});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("unknown tracker \"tail\""), std::string::npos) << bad.err;
}

TEST_F(ToolsTest, SimWritesTheSameLogAsTheLibrary) {
  const fs::path out = dir_ / "walk.csv";
  const ProcessResult r = run("bodyd-sim", {"--bvh", kWalk, "--out", out.string(), "--rate-hz", "90", "--noise-mm", "2",
                                  "--noise-deg", "1", "--dropout-rate", "2", "--latency-ms", "10", "--jitter-ms",
                                  "0.5", "--seed", "7", "--hands-rate-hz", "72"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("left_hand"), std::string::npos) << r.out;  // the summary
  const TrackerLog log = read_tracker_log(out);

  SimOptions opt;
  opt.rate_hz = 90;
  opt.role_rate_hz = {0, 72, 72};
  opt.position_noise_mm = 2;
  opt.rotation_noise_deg = 1;
  opt.dropout_rate_hz = 2;
  opt.latency_ms = 10;
  opt.jitter_ms = 0.5;
  opt.seed = 7;
  ASSERT_TRUE(same_samples(log.samples, simulate_trackers(read_bvh(kWalk), opt), /*rotations=*/true));
  bool has_source = false;
  for (const auto& [k, v] : log.metadata) has_source |= k == "source" && v == "walk_60.bvh";
  EXPECT_TRUE(has_source);

  // '-' writes the log to stdout and the summary to stderr.
  const ProcessResult s = run("bodyd-sim", {"--bvh", kWalk, "--out", "-"});
  ASSERT_EQ(s.exit_code, 0) << s.err;
  EXPECT_EQ(parse_tracker_log(s.out, "stdout").samples.size(), 3u * 177u);
  EXPECT_NE(s.err.find("samples"), std::string::npos);
}

TEST_F(ToolsTest, SimReportsBadInput) {
  const ProcessResult bad_opt = run("bodyd-sim", {"--bvh", kWalk, "--out", (dir_ / "x.csv").string(), "--rate-hz", "-3"});
  EXPECT_EQ(bad_opt.exit_code, 2);
  EXPECT_NE(bad_opt.err.find("rate_hz"), std::string::npos) << bad_opt.err;

  const fs::path bad = dir_ / "bad.bvh";
  std::ofstream(bad) << "HIERARCHY\nROOT x\n{\n  OFFSET 0 0\n}\n";
  const ProcessResult r = run("bodyd-sim", {"--bvh", bad.string(), "--out", (dir_ / "x.csv").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(bad.string() + ":5:"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "x.csv"));

  const ProcessResult missing = run("bodyd-sim", {"--out", (dir_ / "x.csv").string()});
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_EQ(run("bodyd-sim", {"--bvh", kWalk, "--out", "-", "--noise-mm", "abc"}).exit_code, 2);
  EXPECT_NE(missing.err.find("--bvh"), std::string::npos) << missing.err;
}
