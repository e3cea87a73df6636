// The documentation never points to a file that is not in the repository (issue 12): every
// relative Markdown link and every backticked `*.md` path in README.md and docs/ must exist, and
// the conventions are cited from docs/conventions.md, not from a file outside the repository.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "../test_paths.h"
#include "bodyd/test/files.h"

namespace fs = std::filesystem;

namespace {

std::vector<fs::path> markdown_files() {
  const fs::path root = bodyd::test::source_dir();
  std::vector<fs::path> files{root / "README.md"};
  for (const auto& entry : fs::directory_iterator(root / "docs"))
    if (entry.path().extension() == ".md") files.push_back(entry.path());
  for (const char* extra : {"data/README.md", "tests/data/README.md"})
    if (fs::exists(root / extra)) files.push_back(root / extra);
  return files;
}

using bodyd::test::read_file;

// Links and paths that are not files of the repository: URLs, anchors, build outputs, things a
// command makes, and the data that docs/conventions.md says lives beside the checkout.
bool outside_repo(const std::string& target) {
  return target.starts_with("http://") || target.starts_with("https://") || target.starts_with("#") ||
         target.starts_with("mailto:") || target.starts_with("../shared/") || target.starts_with("build") ||
         target.find('*') != std::string::npos || target.find('<') != std::string::npos ||
         target.find('{') != std::string::npos;
}

}  // namespace

TEST(Docs, EveryLinkedFileExists) {
  const fs::path root = bodyd::test::source_dir();
  const std::regex md_link(R"(\]\(([^)\s]+)\))");
  const std::regex md_path("`((?:[A-Za-z0-9_.-]+/)*[A-Za-z0-9_.-]+\\.md)`");
  int checked = 0;
  for (const auto& file : markdown_files()) {
    const std::string text = read_file(file);
    for (std::sregex_iterator it(text.begin(), text.end(), md_link), end; it != end; ++it) {
      std::string target = (*it)[1].str();
      if (const auto hash = target.find('#'); hash != std::string::npos && hash > 0) target.resize(hash);
      if (outside_repo(target)) continue;
      ++checked;
      EXPECT_TRUE(fs::exists(file.parent_path() / target))
          << fs::relative(file, root).string() << " links to " << target << ", which is not in the repository";
    }
    for (std::sregex_iterator it(text.begin(), text.end(), md_path), end; it != end; ++it) {
      const std::string target = (*it)[1].str();
      if (outside_repo(target)) continue;
      // A bare name (`README.md`) is relative to the page; a path with a folder is from the root.
      const bool bare = target.find('/') == std::string::npos;
      const fs::path resolved = bare ? file.parent_path() / target : root / target;
      const bool found = fs::exists(resolved) || (bare && fs::exists(root / target));
      ++checked;
      EXPECT_TRUE(found) << fs::relative(file, root).string() << " names `" << target
                         << "`, which is not in the repository";
    }
  }
  EXPECT_GT(checked, 20) << "the link scanner found almost nothing to check; is the regex broken?";
}

TEST(Docs, ConventionsAreCitedFromTheRepository) {
  const fs::path root = bodyd::test::source_dir();
  ASSERT_TRUE(fs::exists(root / "docs" / "conventions.md"));
  // Sources and docs cite docs/conventions.md; the shared CONVENTIONS.md is not in a user's clone.
  for (const char* dir : {"docs", "motion", "inference", "io", "daemon", "protocol", "client",
                          "render", "tools", "simulators", "viewer", "training", "scripts"}) {
    if (!fs::exists(root / dir)) continue;
    for (const auto& entry : fs::recursive_directory_iterator(root / dir)) {
      if (!entry.is_regular_file()) continue;
      if (entry.path().string().find("node_modules") != std::string::npos) continue;
      const auto ext = entry.path().extension().string();
      if (ext != ".md" && ext != ".h" && ext != ".cpp" && ext != ".py" && ext != ".js" && ext != ".html" &&
          ext != "")
        continue;
      const std::string text = read_file(entry.path());
      EXPECT_EQ(text.find("CONVENTIONS.md"), std::string::npos)
          << fs::relative(entry.path(), root).string()
          << " cites CONVENTIONS.md, which is not in the repository; cite docs/conventions.md";
      EXPECT_EQ(text.find("shared/docs"), std::string::npos)
          << fs::relative(entry.path(), root).string() << " points into ../shared/docs; cite docs/conventions.md";
    }
  }
}

// Issue 20 item 8: the quick start installs the file `make package` writes. Every
// `apt install ./DIR/bodyd_...deb` in README.md and docs/install.md names the Makefile's
// PACKAGE_BUILD directory.
TEST(Docs, AptInstallNamesTheFileMakePackageWrites) {
  const fs::path root = bodyd::test::source_dir();
  std::smatch m;
  const std::string makefile = read_file(root / "Makefile");
  ASSERT_TRUE(std::regex_search(makefile, m, std::regex(R"(\nPACKAGE_BUILD \?= (\S+))")))
      << "the Makefile does not say where make package builds (PACKAGE_BUILD ?= DIR)";
  const std::string dir = m[1].str();
  const std::regex install(R"(apt install (\S*bodyd_\S*\.deb))");
  int found = 0;
  for (const char* page : {"README.md", "docs/install.md"}) {
    const std::string text = read_file(root / page);
    for (std::sregex_iterator it(text.begin(), text.end(), install), end; it != end; ++it) {
      ++found;
      EXPECT_TRUE((*it)[1].str().starts_with("./" + dir + "/bodyd_"))
          << page << ": `" << it->str() << "` is not the file make package writes (" << dir << "/bodyd_*.deb)";
    }
  }
  EXPECT_GE(found, 2);
}

// Issue 20 item 8: what a missing user session bus means for `systemctl --user`, and what to do.
TEST(Docs, InstallExplainsAMissingUserBus) {
  const std::string text = read_file(bodyd::test::source_dir() / "docs/install.md");
  for (const char* part : {"Failed to connect to bus: No medium found", "desktop session", "loginctl enable-linger"})
    EXPECT_NE(text.find(part), std::string::npos) << "docs/install.md does not mention \"" << part << "\"";
}

// Issue 20 item 9: docs/protocol.md's C# section declares every function of the C ABI header
// (a P/Invoke client is written from it), says how many there are, and points to no table that
// is not there.
TEST(Docs, CSharpSectionDeclaresEveryCAbiFunction) {
  const fs::path root = bodyd::test::source_dir();
  const std::string header = read_file(root / "client/include/bodyd_client.h");
  const std::string doc = read_file(root / "docs/protocol.md");
  const std::regex declared(R"(BODYD_API[^;(]*\b(bodyd_client_\w+)\s*\()");
  int functions = 0;
  for (std::sregex_iterator it(header.begin(), header.end(), declared), end; it != end; ++it) {
    ++functions;
    const std::string name = (*it)[1].str();
    EXPECT_TRUE(std::regex_search(doc, std::regex("\\[DllImport\\(Lib\\)\\][^\\n]*\\b" + name + "\\(")))
        << "docs/protocol.md's C# section has no DllImport for " << name;
  }
  EXPECT_GE(functions, 14);
  EXPECT_NE(doc.find("These are all " + std::to_string(functions) + " functions of the header"), std::string::npos)
      << "docs/protocol.md does not say the header has " << functions << " functions";
  EXPECT_EQ(doc.find("the table below"), std::string::npos) << "docs/protocol.md refers to a table below";
  // The retargeting recipe covers what an integrator needs beyond the special case.
  for (const char* part : {"bodyd_client_skeleton_rest_rotation", "A[b]", "hAvatar", "fUser", "UpperChest",
                           "HumanPoseHandler", "facing bodyd −Z"})
    EXPECT_NE(doc.find(part), std::string::npos) << "docs/protocol.md lacks \"" << part << "\"";
}
