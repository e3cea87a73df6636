// The table of control requests (bodyd/daemon/control.h, control_requests()) drives the control
// socket's dispatch. These tests go over every row: docs/control.md has a section for each request
// and none for a request the table lacks, each old name is said in its request's section, and
// the new name of re-centring (recenter) and its old one (reset) both reach the target.
#include "bodyd/daemon/control.h"
#include "../test_paths.h"

#include "bodyd/test/files.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>

namespace bodyd::daemon {
namespace {

std::string text_of(const std::filesystem::path& path) {
  EXPECT_TRUE(std::filesystem::is_regular_file(path)) << path;
  return test::read_file(path);
}

// The part of `text` from the line `heading` ("## ..." or "### ...") to the next heading of the
// same level or higher; empty when there is no such line.
std::string section(const std::string& text, const std::string& heading) {
  const std::size_t start = text.find("\n" + heading + "\n");
  if (start == std::string::npos) return {};
  const std::size_t body = start + 1 + heading.size();
  std::size_t end = text.find("\n## ", body);
  if (heading.rfind("### ", 0) == 0) end = std::min(end, text.find("\n### ", body));
  return text.substr(start + 1, end == std::string::npos ? std::string::npos : end - start - 1);
}

TEST(ControlRequests, NamesAreUniqueAndOldNamesNameARequest) {
  std::set<std::string_view> names, requests;
  for (const ControlRequest& row : control_requests()) {
    EXPECT_TRUE(names.insert(row.name).second) << row.name << " twice in the table";
    EXPECT_FALSE(row.help.empty()) << row.name;
    EXPECT_FALSE(row.docs.empty()) << row.name;
    EXPECT_NE(row.handle, nullptr) << row.name;
    if (row.alias_of.empty()) requests.insert(row.name);
  }
  for (const ControlRequest& row : control_requests()) {
    if (row.alias_of.empty()) continue;
    EXPECT_TRUE(requests.count(row.alias_of)) << row.name << " is the old name of " << row.alias_of << ", not a request";
    EXPECT_EQ(row.docs, row.alias_of) << row.name << ": an old name is documented in its request's section";
  }
}

// docs/control.md's "Commands" lists exactly the table's requests, one "### `NAME`" section
// each; each section shows its request ({"cmd": "NAME"}), and an old name is in its request's.
TEST(ControlRequests, DocsListExactlyTheRequests) {
  const std::string doc = text_of(test::source_dir() / "docs" / "control.md");
  const std::string commands = section(doc, "## Commands");
  ASSERT_FALSE(commands.empty()) << "docs/control.md has no section \"## Commands\"";
  std::set<std::string> documented;
  const std::regex heading(R"((^|\n)### `([^`]+)`)");
  for (auto it = std::sregex_iterator(commands.begin(), commands.end(), heading); it != std::sregex_iterator(); ++it)
    documented.insert((*it)[2].str());

  std::set<std::string> requests;
  for (const ControlRequest& row : control_requests()) {
    if (row.alias_of.empty()) requests.insert(std::string(row.name));
    const std::string part = section(commands, "### `" + std::string(row.docs) + "`");
    if (part.empty()) {
      ADD_FAILURE() << row.name << ": docs/control.md has no section \"### `" << row.docs << "`\"";
      continue;
    }
    EXPECT_NE(part.find("\"cmd\": \"" + std::string(row.name) + "\""), std::string::npos)
        << "docs/control.md's section \"" << row.docs << "\" never shows {\"cmd\": \"" << row.name << "\"}";
  }
  for (const std::string& name : requests)
    EXPECT_TRUE(documented.count(name)) << "the request " << name << " is not in docs/control.md's \"Commands\"";
  for (const std::string& name : documented)
    EXPECT_TRUE(requests.count(name)) << "docs/control.md documents \"" << name << "\", which the table of requests lacks";
}

// A target that records which function a request reached.
struct RecentreTarget final : ControlTarget {
  int recentred = 0;
  nlohmann::json status() override { return {{"ok", true}}; }
  nlohmann::json skeleton() override { return {{"ok", true}}; }
  nlohmann::json calibrate_height(double) override { return {{"ok", true}}; }
  nlohmann::json calibrate_from_head() override { return {{"ok", true}}; }
  nlohmann::json reload_model(const std::optional<std::string>&) override { return {{"ok", true}}; }
  nlohmann::json shutdown() override { return {{"ok", true}}; }
  nlohmann::json recentre() override {
    ++recentred;
    return {{"ok", true}, {"recentred", true}};
  }
};

// Issue 45 item 4: the request is "recenter"; "reset", its old name, still works.
TEST(ControlRequests, RecenterAndItsOldNameResetRecentre) {
  RecentreTarget t;
  EXPECT_EQ(handle_control_request(R"({"cmd":"recenter"})", t), (nlohmann::json{{"ok", true}, {"recentred", true}}));
  EXPECT_EQ(t.recentred, 1);
  EXPECT_EQ(handle_control_request(R"({"cmd":"reset"})", t), (nlohmann::json{{"ok", true}, {"recentred", true}}));
  EXPECT_EQ(t.recentred, 2);
  // Each name in its own messages; neither takes a key.
  EXPECT_EQ(handle_control_request(R"({"cmd":"recenter","now":true})", t)["error"],
            "unknown key \"now\" for cmd \"recenter\" (allowed: cmd)");
  EXPECT_EQ(handle_control_request(R"({"cmd":"reset","now":true})", t)["error"],
            "unknown key \"now\" for cmd \"reset\" (allowed: cmd)");
  EXPECT_EQ(t.recentred, 2);
  // The list of requests names the new name, not the old one.
  EXPECT_EQ(handle_control_request(R"({"cmd":"recentre"})", t)["error"],
            "unknown cmd \"recentre\" (one of status, skeleton, calibrate, recenter, reload-model, shutdown)");
}

}  // namespace
}  // namespace bodyd::daemon
