// Split files (motion/include/bodyd/motion/split_file.h): the one C++ reader that bodyd-dataset,
// bodyd-eval and bodyd-bvh share, and training/train.py's read_clip_list following the same rule.
#include "bodyd/motion/split_file.h"

#include "../test_paths.h"
#include "bodyd/test/files.h"
#include "bodyd/test/process.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace bodyd {
namespace {

namespace fs = std::filesystem;

// A dataset root with splits/ and two clip files.
class SplitFile : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::create_directories(root_ / "splits");
    fs::create_directories(root_ / "clips");
    ASSERT_TRUE(test::write_file(root_ / "clips" / "a.bvh", "x"));
    ASSERT_TRUE(test::write_file(root_ / "clips" / "b#2.bvh", "x"));
  }
  fs::path split(const std::string& name, const std::string& text) {
    const fs::path p = root_ / "splits" / name;
    EXPECT_TRUE(test::write_file(p, text));
    return p;
  }
  std::string message(const fs::path& p) {
    try {
      (void)read_split(p);
    } catch (const UserError& e) {
      return e.what();
    }
    return "(no error)";
  }
  test::TempDir dir_{"bodyd-split-test"};
  const fs::path root_ = dir_.path;
};

TEST(SplitLine, TheLineRule) {
  EXPECT_EQ(split_line_path("clips/a.bvh"), "clips/a.bvh");
  EXPECT_EQ(split_line_path("clips/a.bvh\r"), "clips/a.bvh");
  EXPECT_EQ(split_line_path(" \tclips/a.bvh \t\r"), "clips/a.bvh");
  EXPECT_EQ(split_line_path("clips/my clip.bvh"), "clips/my clip.bvh");  // inner spaces stay
  EXPECT_EQ(split_line_path("clips/b#2.bvh"), "clips/b#2.bvh");          // '#' later is part of the path
  EXPECT_EQ(split_line_path(""), "");
  EXPECT_EQ(split_line_path(" \t\r"), "");
  EXPECT_EQ(split_line_path("# clips/a.bvh"), "");
  EXPECT_EQ(split_line_path("   # indented comment"), "");
}

TEST_F(SplitFile, CommentsBlanksWhitespaceAndCrlfReadAlike) {
  const auto unix_paths = read_split(split("unix.txt", "# the clips\n\nclips/a.bvh\nclips/b#2.bvh\n"));
  const auto crlf_paths = read_split(split("crlf.txt", "# the clips\r\n\r\n  clips/a.bvh\t\r\n\tclips/b#2.bvh  \r\n  # end\r\n"));
  const auto no_newline = read_split(split("last.txt", "clips/a.bvh\nclips/b#2.bvh"));
  const std::vector<fs::path> expected = {root_ / "clips" / "a.bvh", root_ / "clips" / "b#2.bvh"};
  EXPECT_EQ(unix_paths, expected);
  EXPECT_EQ(crlf_paths, expected);
  EXPECT_EQ(no_newline, expected);
}

TEST_F(SplitFile, AbsolutePathsAreTakenAsTheyAre) {
  const fs::path a = root_ / "clips" / "a.bvh";
  EXPECT_EQ(read_split(split("abs.txt", a.string() + "\n")), std::vector<fs::path>{a});
}

TEST_F(SplitFile, ErrorsNameTheFileAndLine) {
  EXPECT_NE(message(split("missing.txt", "clips/a.bvh\n\nclips/missing.bvh\n")).find("missing.txt:3: "), std::string::npos);
  EXPECT_NE(message(root_ / "splits" / "none.txt").find("none.txt: cannot open the split file"), std::string::npos);
  // An empty split, or one of comments only, is a mistake, not an empty data set.
  EXPECT_NE(message(split("empty.txt", "")).find("empty.txt: the split lists no files"), std::string::npos);
  EXPECT_NE(message(split("comments.txt", "# nothing yet\r\n\r\n")).find("lists no files"), std::string::npos);
}

// training/train.py reads its clip lists with read_clip_list; run it (extracted from the file, so
// without PyTorch) on the same lines and compare with split_line_path.
TEST_F(SplitFile, TrainPyReadsListsByTheSameRule) {
  if (test::shell("python3 -c 'import ast' 2>&1").status != 0) GTEST_SKIP() << "no python3";
  const std::string text = "# c\r\n\r\n  clips/a.bvh\t\r\n\tclips/b#2.bvh  \n   # indented\nclips/x y.bvh\n\n";
  const fs::path list = split("list.txt", text);
  const fs::path script = root_ / "read.py";
  ASSERT_TRUE(test::write_file(script,
                               "import ast, os, sys\n"
                               "src = open(sys.argv[1]).read()\n"
                               "fn = next(n for n in ast.parse(src).body\n"
                               "          if isinstance(n, ast.FunctionDef) and n.name == 'read_clip_list')\n"
                               "ns = {'os': os, 'sys': sys}\n"
                               "exec(compile(ast.Module(body=[fn], type_ignores=[]), 'train.py', 'exec'), ns)\n"
                               "sys.stdout.write(''.join(p + '\\n' for p in ns['read_clip_list'](sys.argv[2])))\n"));
  const std::string read_py =
      "python3 '" + script.string() + "' '" + (test::source_dir() / "training" / "train.py").string() + "' ";
  const test::ShellResult py = test::shell(read_py + "'" + list.string() + "'");
  ASSERT_EQ(py.status, 0) << read_py;
  std::string cpp;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);)
    if (const std::string_view p = split_line_path(line); !p.empty()) cpp += std::string(p) + "\n";
  EXPECT_EQ(py.out, cpp);
  EXPECT_EQ(cpp, "clips/a.bvh\nclips/b#2.bvh\nclips/x y.bvh\n");
  // And both refuse a list that names nothing.
  const fs::path empty = split("empty_list.txt", "# nothing\r\n");
  EXPECT_NE(test::shell(read_py + "'" + empty.string() + "' 2>&1").status, 0);
}

}  // namespace
}  // namespace bodyd
