// training/style-heldout.txt and style-heldout-b.txt (issue 18 item 1, issue 44; docs/evaluation.md
// "Style-held-out protocol"): every training clip (splits/train.txt and splits/train-extra.txt) of each set's
// documented styles, and nothing else; no clip in both sets. Read with the project's one split reader (read_split) and
// style parser (clip_groups). Skipped when ../shared/data is absent.
#include "bodyd/inference/evaluation.h"
#include "bodyd/motion/split_file.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <fstream>
#include <set>
#include <string>
#include <utility>

using namespace bodyd;

namespace {

// The two held-out sets (issue 44: choices are made on more than one set of unseen styles).
struct HeldOutSet {
  const char* file;
  std::set<std::pair<std::string, std::string>> styles;
  std::size_t expected;  // clips of splits/train.txt and splits/train-extra.txt
};
const HeldOutSet kSets[] = {
    // 120 + 267 dataset-2 youthful, 10 each of childish, not-confident, giant
    {"style-heldout.txt",
     {{"dataset-2", "youthful"}, {"dataset-1", "childish"}, {"dataset-1", "not-confident"}, {"dataset-1", "giant"}},
     417},
    // 113 + 252 dataset-2 masculine, 10 angry, 9 happy, 9 musical
    {"style-heldout-b.txt",
     {{"dataset-2", "masculine"}, {"dataset-1", "angry"}, {"dataset-1", "happy"}, {"dataset-1", "musical"}},
     393},
};

// The split's clips as dataset-root-relative strings ("dataset-1/....bvh").
std::set<std::string> relative(const std::vector<std::filesystem::path>& clips, const std::filesystem::path& root) {
  std::set<std::string> out;
  for (const auto& c : clips) out.insert(c.lexically_relative(root).generic_string());
  return out;
}

// training/FILE lists paths relative to the dataset root; read_split resolves a split file's paths
// against its folder's parent, so read it as ROOT/splits/FILE with ROOT's dataset-N folders linked to the
// real ones.
std::set<std::string> style_heldout(const char* file, size_t* lines) {
  const std::filesystem::path root =
      std::filesystem::temp_directory_path() / ("bodyd_style_heldout_" + std::to_string(::getpid()));
  std::filesystem::remove_all(root);
  std::filesystem::create_directories(root / "splits");
  for (const char* d : {"dataset-1", "dataset-2"}) std::filesystem::create_directory_symlink(test::bandai() / d, root / d);
  std::filesystem::copy_file(test::source_dir() / "training" / file, root / "splits" / file);
  const auto clips = read_split(root / "splits" / file);  // throws if a listed file does not exist
  std::filesystem::remove_all(root);
  *lines = clips.size();
  return relative(clips, root);
}

// Every training clip: splits/train.txt and splits/train-extra.txt.
std::vector<std::filesystem::path> training_clips() {
  const std::filesystem::path root = test::bandai();
  std::vector<std::filesystem::path> clips = read_split(root / "splits" / "train.txt");
  const auto extra = read_split(root / "splits" / "train-extra.txt");
  clips.insert(clips.end(), extra.begin(), extra.end());
  return clips;
}

}  // namespace

TEST(StyleHeldout, ListsOnlyTrainingSplitClipsOnce) {
  if (!test::have_bandai()) GTEST_SKIP() << "no ../shared/data/bandai-namco";
  const std::filesystem::path root = test::bandai();
  const std::set<std::string> train = relative(training_clips(), root);
  const std::set<std::string> val = relative(read_split(root / "splits" / "val.txt"), root);
  std::set<std::string> seen;
  for (const HeldOutSet& set : kSets) {
    SCOPED_TRACE(set.file);
    size_t lines = 0;
    const std::set<std::string> held = style_heldout(set.file, &lines);
    EXPECT_EQ(held.size(), lines) << "a clip is listed twice";
    for (const std::string& c : held) {
      EXPECT_TRUE(train.count(c)) << c << " is not in splits/train.txt or splits/train-extra.txt";
      EXPECT_FALSE(val.count(c)) << c << " is in splits/val.txt";
      EXPECT_TRUE(seen.insert(c).second) << c << " is in both sets";
    }
  }
}

TEST(StyleHeldout, IsEveryTrainingClipOfTheDocumentedStyles) {
  if (!test::have_bandai()) GTEST_SKIP() << "no ../shared/data/bandai-namco";
  const std::filesystem::path root = test::bandai();
  for (const HeldOutSet& set : kSets) {
    SCOPED_TRACE(set.file);
    size_t lines = 0;
    const std::set<std::string> held = style_heldout(set.file, &lines);
    size_t expected = 0;
    for (const auto& clip : training_clips()) {
      const auto g = clip_groups(clip);
      const bool chosen = set.styles.count({g[0], g[2]}) > 0;
      expected += chosen;
      const std::string rel = clip.lexically_relative(root).generic_string();
      EXPECT_EQ(held.count(rel) > 0, chosen) << rel << " (style " << g[0] << " " << g[2] << ")";
    }
    EXPECT_EQ(held.size(), expected);
    EXPECT_EQ(expected, set.expected);
    // The header names each held-out style; 'normal' stays in training.
    std::ifstream in(test::source_dir() / "training" / set.file);
    std::string header, line;
    while (std::getline(in, line))
      if (!line.empty() && line[0] == '#') header += line + "\n";
    for (const auto& [dataset, style] : set.styles) EXPECT_NE(header.find(style), std::string::npos) << style;
    for (const std::string& c : held) EXPECT_NE(clip_groups(c)[2], "normal") << c;
  }
}
