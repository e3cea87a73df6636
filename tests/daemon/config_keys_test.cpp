// The config key table (bodyd/daemon/config_keys.h) drives the parser, the validator, the
// printer and the flags. These tests go over every row, so a key the printer forgets, a flag
// that sets nothing, a key docs/daemon.md or the fuzz seed does not list, or a flag --help has
// and the docs do not, fails here.
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/config_keys.h"
#include "bodyd/io/output.h"
#include "../test_paths.h"

#include "bodyd/test/files.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

namespace bodyd::daemon {
namespace {

using nlohmann::json;

std::string text_of(const std::filesystem::path& path) {
  EXPECT_TRUE(std::filesystem::is_regular_file(path)) << path;
  return test::read_file(path);
}

std::string number_text(double x) {
  std::ostringstream s;
  s.precision(17);
  s << x;
  return s.str();
}

// Sets the key in `config` to a value other than its default that still passes validation,
// and returns that value as its flag takes it ("" for a bool flag).
std::string set_other_value(const ConfigKey& row, DaemonConfig& config) {
  return with_member(row, config, [&](auto& member) -> std::string {
    using T = std::remove_reference_t<decltype(member)>;
    if constexpr (std::is_same_v<T, bool>) {
      member = !member;
      return "";
    } else if constexpr (std::is_integral_v<T>) {
      member += 1;
      return std::to_string(member);
    } else if constexpr (std::is_floating_point_v<T>) {
      member = member == 0.0 ? 0.5 : member * 1.5;
      return number_text(member);
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (!row.choices.empty()) {
        std::stringstream choices{std::string(row.choices)};
        for (std::string choice; std::getline(choices, choice, ',');)
          if (choice != member) return member = choice;
      }
      return member = member.empty() ? "other" : member + "-other";
    } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
      // A well-formed spec of the list (check_specs runs on the flags' values).
      const std::string spec = row.name == "sources"   ? "replay:other.csv"
                               : row.name == "outputs" ? "vrchat:127.0.0.1:9000"
                                                       : "";
      EXPECT_FALSE(spec.empty()) << row.full_name() << ": give this test an example value of the new list key";
      member = {spec};
      return spec;
    } else {
      static_assert(std::is_same_v<T, DeviceOffsets>);
      member[0] = DeviceOffset{Vec3(0.01, 0.02, 0.03), Quat::Identity()};
      return "head=0.01,0.02,0.03";
    }
  });
}

// Whether the key holds the same value in both (read through the row, not the printer).
bool same_value(const ConfigKey& row, DaemonConfig a, DaemonConfig b) {
  const auto same = [](const auto& x, const auto& y) {
    if constexpr (std::is_same_v<std::remove_cvref_t<decltype(x)>, DeviceOffsets>) {
      for (std::size_t r = 0; r < x.size(); ++r) {
        if (x[r].has_value() != y[r].has_value()) return false;
        if (x[r] && (!x[r]->position_m.isApprox(y[r]->position_m) ||
                     !x[r]->rotation.coeffs().isApprox(y[r]->rotation.coeffs())))
          return false;
      }
      return true;
    } else {
      return x == y;
    }
  };
  return with_member(row, a, [&](const auto& x) {
    return with_member(row, b, [&](const auto& y) -> bool {
      if constexpr (std::is_same_v<decltype(x), decltype(y)>)
        return same(x, y);
      else
        return false;
    });
  });
}

// "" when `have` is `want`, else what is missing and what is extra.
std::string difference(const std::set<std::string>& have, const std::set<std::string>& want) {
  std::string missing, extra;
  for (const std::string& k : want)
    if (!have.count(k)) missing += " " + k;
  for (const std::string& k : have)
    if (!want.count(k)) extra += " " + k;
  return (missing.empty() ? "" : "missing:" + missing) + (extra.empty() ? "" : " extra (not in the table):" + extra);
}

std::set<std::string> table_names() {
  std::set<std::string> names;
  for (const ConfigKey& row : config_keys()) names.insert(row.full_name());
  return names;
}

// The keys of a config JSON object, "sim.seed" for a key inside an object of keys.
std::set<std::string> json_key_names(const json& j) {
  std::set<std::string> names;
  for (const auto& [key, value] : j.items()) {
    bool group = false;
    for (const ConfigGroup& g : config_groups()) group |= g.name == key;
    if (group && value.is_object())
      for (const auto& [inner, ignored] : value.items()) names.insert(key + "." + inner);
    else
      names.insert(key);
  }
  return names;
}

std::string flag_name(const ConfigKey& row) { return row.flag.starts_with('!') ? row.flag.substr(1) : row.flag; }

// docs/daemon.md from "## title" to the next "## ".
std::string doc_section(const std::string& doc, const std::string& title) {
  const auto start = doc.find("\n## " + title + "\n");
  EXPECT_NE(start, std::string::npos) << "docs/daemon.md has no section \"" << title << "\"";
  if (start == std::string::npos) return {};
  const auto end = doc.find("\n## ", start + 1);
  return doc.substr(start, end == std::string::npos ? std::string::npos : end - start);
}

std::vector<std::string> backticked(const std::string& text) {
  std::vector<std::string> out;
  static const std::regex kTick("`([^`]+)`");
  for (std::sregex_iterator it(text.begin(), text.end(), kTick), end; it != end; ++it) out.push_back((*it)[1]);
  return out;
}

// The table rows (cells) of a markdown section.
std::vector<std::vector<std::string>> table_lines(const std::string& section) {
  std::vector<std::vector<std::string>> lines;
  std::stringstream in(section);
  for (std::string line; std::getline(in, line);) {
    if (!line.starts_with("| ") || line.starts_with("| ---")) continue;
    std::vector<std::string> cells;
    std::stringstream cs(line.substr(1));
    for (std::string cell; std::getline(cs, cell, '|');) cells.push_back(cell);
    lines.push_back(cells);
  }
  return lines;
}

// ---------------------------------------------------------------------------------------------

TEST(ConfigKeys, NamesAndFlagsAreUnique) {
  std::set<std::string> names, flags;
  for (const ConfigKey& row : config_keys()) {
    EXPECT_TRUE(names.insert(row.full_name()).second) << row.full_name();
    if (!row.flag.empty()) { EXPECT_TRUE(flags.insert(flag_name(row)).second) << row.flag; }
    EXPECT_FALSE(row.help.empty()) << row.full_name();
    EXPECT_FALSE(row.doc.empty()) << row.full_name();
  }
  for (std::string_view flag : kNonKeyFlags) EXPECT_FALSE(flags.count(std::string(flag))) << flag;
  // The simulator's rows are spliced in whole.
  for (const SimOptionKey& sim : sim_option_keys()) EXPECT_TRUE(find_config_key("sim." + std::string(sim.key)));
}

// The printer forgetting a key, or printing one the parser does not take, fails here: each
// key set alone to a value other than its default reads back from what --print-config writes.
TEST(ConfigKeys, EveryKeyRoundTripsThroughThePrinter) {
  EXPECT_EQ(difference(json_key_names(config_to_json(DaemonConfig{})), table_names()), "") << "--print-config";
  for (const ConfigKey& row : config_keys()) {
    DaemonConfig config;
    set_other_value(row, config);
    ASSERT_FALSE(same_value(row, config, DaemonConfig{})) << row.full_name() << ": the test's value is the default";
    const json printed = config_to_json(config);
    DaemonConfig again;
    ASSERT_EQ(apply_config_json(printed, "printed", again), "") << row.full_name();
    EXPECT_TRUE(same_value(row, again, config)) << row.full_name() << " does not survive print and parse: "
                                                << printed.dump();
    EXPECT_EQ(config_to_json(again), printed) << row.full_name();
  }
}

// Each flag sets its key (and only through parse_command_line, as bodyd runs it).
TEST(ConfigKeys, EveryFlagSetsItsKey) {
  for (const ConfigKey& row : config_keys()) {
    if (row.flag.empty()) continue;
    DaemonConfig expected;
    const std::string value = set_other_value(row, expected);
    std::vector<std::string> args{"bodyd"};
    if (row.name == "curve_allow") args.insert(args.end(), {"--curve-secret-key", "k"});  // needs it (validate_config)
    args.push_back(flag_name(row));
    const bool is_flag = with_member(row, expected, [](const auto& member) {
      return std::is_same_v<std::remove_cvref_t<decltype(member)>, bool>;
    });
    if (!is_flag) args.push_back(value);
    std::vector<const char*> argv;
    for (const auto& a : args) argv.push_back(a.c_str());
    DaemonConfig config;
    const CliResult r = parse_command_line(static_cast<int>(argv.size()), argv.data(), config);
    ASSERT_EQ(r.action, CliResult::Action::Run) << row.flag << " " << value;
    EXPECT_TRUE(same_value(row, config, expected)) << row.flag << " " << value << " does not set " << row.full_name();
  }
}

// A key with a range refuses the values just outside it, naming the key, and takes its ends.
TEST(ConfigKeys, RangesAndChoicesAreChecked) {
  int checked = 0;
  for (const ConfigKey& row : config_keys()) {
    const auto set = [&](DaemonConfig& c, double v) {
      with_member(row, c, [&](auto& member) {
        using T = std::remove_reference_t<decltype(member)>;
        if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) member = static_cast<T>(v);
      });
    };
    const auto error_for = [&](double v) {
      DaemonConfig c;
      set(c, v);
      return validate_config(c);
    };
    if (!row.range.error.empty()) {
      ++checked;
      const bool integer = !std::holds_alternative<ConfigRef<double>>(row.field);
      const double step = integer ? 1.0 : 1e-6;
      EXPECT_EQ(error_for(row.range.max), "") << row.full_name();
      if (!row.range.min_exclusive) { EXPECT_EQ(error_for(row.range.min), "") << row.full_name(); }
      std::vector<double> bad{row.range.min - (row.range.min_exclusive ? 0.0 : step)};
      if (!integer || row.range.max < 2147483647.0) bad.push_back(row.range.max + step);  // not past the type
      if (!integer) bad.push_back(std::nan(""));
      if (row.range.zero_allowed) { EXPECT_EQ(error_for(0.0), "") << row.full_name(); }
      for (double v : bad) {
        if (integer && v < 0.0 && !std::holds_alternative<ConfigRef<int>>(row.field)) continue;  // unsigned
        if (row.range.zero_allowed && v == 0.0) continue;
        const std::string e = error_for(v);
        EXPECT_NE(e.find(row.full_name()), std::string::npos) << row.full_name() << " = " << v << ": " << e;
        EXPECT_EQ(e.find('{'), std::string::npos) << e;  // every placeholder replaced
      }
    }
    if (!row.choices.empty()) {
      ++checked;
      std::stringstream choices{std::string(row.choices)};
      for (std::string choice; std::getline(choices, choice, ',');) {
        DaemonConfig c;
        std::get<ConfigRef<std::string>>(row.field)(c) = choice;
        EXPECT_EQ(validate_config(c), "") << row.full_name() << " " << choice;
      }
      DaemonConfig c;
      std::get<ConfigRef<std::string>>(row.field)(c) = "bogus";
      EXPECT_NE(validate_config(c).find(row.full_name() + " \"bogus\": expected "), std::string::npos);
    }
  }
  EXPECT_GE(checked, 9);
}

// docs/daemon.md lists exactly the table's keys: each flag with its key in the "Command line"
// table, each key in the section its row names, and nothing the table does not have.
TEST(ConfigKeys, DocsListExactlyTheKeys) {
  const std::string doc = text_of(test::source_dir() / "docs" / "daemon.md");
  const std::string command_line = doc_section(doc, "Command line");
  const auto lines = table_lines(command_line);
  const std::set<std::string> names = table_names();
  for (const ConfigKey& row : config_keys()) {
    EXPECT_NE(doc_section(doc, std::string(row.doc)).find("`" + std::string(row.name) + "`"), std::string::npos)
        << row.full_name() << " is not in docs/daemon.md, \"" << row.doc << "\"";
    if (row.flag.empty()) continue;
    bool listed = false;
    for (const auto& cells : lines) {
      if (cells.size() < 3) continue;
      const auto flags = backticked(cells[0]), keys = backticked(cells[1]);
      bool has_flag = false;
      for (const std::string& f : flags) has_flag |= f == flag_name(row) || f.starts_with(flag_name(row) + " ");
      listed |= has_flag && std::find(keys.begin(), keys.end(), row.full_name()) != keys.end();
    }
    EXPECT_TRUE(listed) << "docs/daemon.md's \"Command line\" table has no line with " << flag_name(row) << " and "
                        << row.full_name();
  }
  for (const auto& cells : lines) {
    if (cells.size() < 3) continue;
    for (const std::string& key : backticked(cells[1]))
      EXPECT_TRUE(names.count(key)) << "docs/daemon.md lists a config key the table does not have: " << key;
  }
  // The filters' tables and the "sim" paragraph list their group's keys, no more.
  for (const auto& cells : table_lines(doc_section(doc, "Tracker filter")))
    for (const std::string& key : backticked(cells[0]))
      if (key != "key") {
        EXPECT_TRUE(names.count("filter." + key)) << "filter." << key;
      }
  for (const auto& cells : table_lines(doc_section(doc, "Body filter")))
    for (const std::string& key : backticked(cells[0]))
      if (key != "key") {
        EXPECT_TRUE(names.count("body_filter." + key)) << "body_filter." << key;
      }
  const auto sim_at = command_line.find("The `sim` object");
  ASSERT_NE(sim_at, std::string::npos);
  const std::string sim_paragraph = command_line.substr(sim_at, command_line.find("\n\n", sim_at) - sim_at);
  for (const std::string& key : backticked(sim_paragraph))
    if (std::regex_match(key, std::regex("[a-z_]+")) && key != "sim") {
      EXPECT_TRUE(names.count("sim." + key)) << "the sim paragraph lists " << key;
    }
  for (const SimOptionKey& sim : sim_option_keys())
    EXPECT_NE(sim_paragraph.find("`" + std::string(sim.key) + "`"), std::string::npos) << sim.key;

  // The example of "Config file" has every key and reads.
  const std::string config_file = doc_section(doc, "Config file");
  const auto open = config_file.find("```json\n"), close = config_file.find("```\n", open + 8);
  ASSERT_NE(open, std::string::npos);
  const json example = json::parse(config_file.substr(open + 8, close - open - 8), nullptr, false, true);
  ASSERT_FALSE(example.is_discarded());
  EXPECT_EQ(difference(json_key_names(example), names), "") << "the example of docs/daemon.md, \"Config file\"";
  DaemonConfig c;
  EXPECT_EQ(apply_config_json(example, "docs/daemon.md", c), "");
}

// What bodyd --help prints (parse_command_line prints it and asks to exit).
std::string help_text() {
  DaemonConfig c;
  const char* argv[] = {"bodyd", "--help"};
  testing::internal::CaptureStdout();
  const CliResult r = parse_command_line(2, argv, c);
  std::string help = testing::internal::GetCapturedStdout();
  EXPECT_EQ(r.action, CliResult::Action::Exit);
  return help;
}

// Every flag --help shows is in docs/daemon.md's "Command line" section, and every key's flag
// is in --help.
TEST(ConfigKeys, HelpAndDocsHaveTheSameFlags) {
  const std::string command_line = doc_section(text_of(test::source_dir() / "docs" / "daemon.md"), "Command line");
  const std::string help = help_text();
  std::set<std::string> help_flags;
  static const std::regex kFlag("(^|[\\s,])(--[a-z][a-z-]*)");
  for (std::sregex_iterator it(help.begin(), help.end(), kFlag), end; it != end; ++it) help_flags.insert((*it)[2]);
  for (const ConfigKey& row : config_keys())
    if (!row.flag.empty()) { EXPECT_TRUE(help_flags.count(flag_name(row))) << row.flag << " is not in --help"; }
  std::set<std::string> doc_flags;  // every --flag inside `...` of the section
  static const std::regex kDocFlag("--[a-z][a-z-]*");
  for (const std::string& code : backticked(command_line))
    for (std::sregex_iterator it(code.begin(), code.end(), kDocFlag), end; it != end; ++it) doc_flags.insert(it->str());
  for (const std::string& flag : help_flags)
    EXPECT_TRUE(doc_flags.count(flag)) << flag << " (in --help) is not in docs/daemon.md, \"Command line\"";
}

// --output's help lists every registered output kind by its help line (io/outputs.cpp).
TEST(ConfigKeys, HelpListsEveryOutputKind) {
  const std::string help = help_text();
  ASSERT_FALSE(output_kinds().empty());
  for (const OutputKind& kind : output_kinds())
    EXPECT_NE(help.find(std::string(kind.help)), std::string::npos) << kind.scheme << "'s line is not in --help";
}

// The fuzz seed with every key (tests/fuzz/config/full.json) has every key of the table.
TEST(ConfigKeys, FuzzSeedHasEveryKey) {
  const json seed = json::parse(text_of(test::source_dir() / "tests" / "fuzz" / "config" / "full.json"), nullptr, false,
                                true);
  ASSERT_FALSE(seed.is_discarded());
  EXPECT_EQ(difference(json_key_names(seed), table_names()), "") << "tests/fuzz/config/full.json";
  DaemonConfig c;
  EXPECT_EQ(apply_config_json(seed, "full.json", c), "");
}

// The simulator's table: validate() refuses each number just outside its row's range, naming
// the key as its message always did.
TEST(SimOptionKeys, ValidateChecksEachRowsRange) {
  int checked = 0;
  for (const SimOptionKey& row : sim_option_keys()) {
    auto* field = std::get_if<double& (*)(SimOptions&)>(&row.field);
    if (!field) continue;
    ++checked;
    const std::string name(row.message_name.empty() ? row.key : row.message_name);
    for (double ok : {row.min, row.max}) {
      SimOptions o;
      (*field)(o) = ok;
      EXPECT_EQ(o.validate(), "") << row.key << " " << ok;
    }
    for (double bad : {row.min - 1e-4, row.max * 1.01 + 1e-3, std::nan("")}) {
      SimOptions o;
      (*field)(o) = bad;
      if (row.zero_means_unset && bad == 0.0) continue;
      EXPECT_EQ(o.validate().rfind(name + " ", 0), 0u) << row.key << " " << bad << ": " << o.validate();
    }
  }
  EXPECT_EQ(checked, 10);
  SimOptions o;
  o.role_rate_hz[1] = -5;
  EXPECT_EQ(o.validate(), "role_rate_hz[left_hand] -5 must be 0 (use rate_hz) or between 0.001 and 10000 Hz");
  o = {};
  o.dropout_rate_hz = 2000;
  EXPECT_EQ(o.validate(), "dropout_rate_hz 2000 must be between 0 and 1000 episodes per second");
}

std::string output_of(const std::string& command) {
  std::string out;
  if (FILE* pipe = ::popen((command + " 2>&1").c_str(), "r")) {
    char buffer[4096];
    for (std::size_t n; (n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0;) out.append(buffer, n);
    ::pclose(pipe);
  }
  return out;
}

// The flags a tool's --help names.
std::set<std::string> help_flags(const std::string& help) {
  std::set<std::string> flags;
  static const std::regex kFlag("(^|[\\s,!])(--[a-z][a-z-]*)");
  for (std::sregex_iterator it(help.begin(), help.end(), kFlag), end; it != end; ++it) flags.insert((*it)[2]);
  return flags;
}

// bodyd-sim and bodyd-eval take every row's flag and its older spellings.
TEST(SimOptionKeys, BothToolsTakeEveryRowsFlags) {
  for (const char* tool : {"bodyd-sim", "bodyd-eval"}) {
    const std::string help = output_of((test::bin_dir() / tool).string() + " --help");
    const std::set<std::string> flags = help_flags(help);
    for (const SimOptionKey& row : sim_option_keys()) {
      EXPECT_TRUE(flags.count(std::string(row.flag))) << tool << " has no " << row.flag << ":\n" << help;
      std::stringstream aliases{std::string(row.aliases)};
      for (std::string alias; std::getline(aliases, alias, ',');)
        EXPECT_TRUE(flags.count(alias)) << tool << " has no " << alias;
    }
  }
  // An older spelling sets what the flag sets (bodyd-sim writes its options in the log).
  const std::string sim = (test::bin_dir() / "bodyd-sim").string() + " --quiet --out - --bvh " +
                          (test::fixtures() / "walk_60.bvh").string();
  const std::string by_flag = output_of(sim + " --dropout-mean-ms 123 --rate-hz 45");
  EXPECT_NE(by_flag.find("mean_ms=123"), std::string::npos) << by_flag.substr(0, 2000);
  EXPECT_EQ(output_of(sim + " --dropout-ms 123 --tracker-rate-hz 45"), by_flag);
}

// bodyd-eval takes one flag per row of the filters' table, the daemon's "filter" and "body_filter"
// keys (issue 45 item 4), and each sets its own key: a bad value is refused naming that key.
TEST(FilterOptionKeys, EvalTakesEveryRowsFlagAndSetsItsKey) {
  const std::string eval = (test::bin_dir() / "bodyd-eval").string();
  const std::set<std::string> flags = help_flags(output_of(eval + " --help"));
  const std::string clip = " --methods ik " + (test::fixtures() / "walk_60.bvh").string();
  int numbers = 0;
  for (const FilterOptionKey& row : filter_option_keys()) {
    std::string flag = filter_flag(row);
    if (flag.starts_with('!')) flag.erase(0, 1);
    EXPECT_TRUE(flags.count(flag)) << "bodyd-eval has no " << flag << " for " << row.full_name();
    std::vector<std::string> names{flag};
    std::stringstream aliases{std::string(row.eval_aliases)};
    for (std::string alias; std::getline(aliases, alias, ',');) names.push_back(alias);
    if (!std::holds_alternative<double& (*)(FilterSettings)>(row.field)) continue;
    ++numbers;
    for (const std::string& name : names) {
      const std::string out = output_of(eval + " " + name + " -1" + clip);
      EXPECT_NE(out.find(std::string(row.group) + " " + std::string(row.name) + " must be"), std::string::npos)
          << name << " -1: " << out;
    }
  }
  EXPECT_EQ(numbers, 14);
}

// The "body_filter" keys (issue 18 item 4) parse, print back, are checked, and --no-body-filter
// turns the filter off (it is on by default).
TEST(ConfigKeys, BodyFilterParsesValidatesAndPrints) {
  DaemonConfig c;
  EXPECT_TRUE(c.body_filter.enabled);
  const json text = json::parse(R"({"body_filter": {"enabled": false, "min_cutoff_hz": 1.5,
      "beta_per_m_s": 0.5, "d_cutoff_hz": 2, "rot_min_cutoff_hz": 3, "rot_beta_per_rad_s": 0.25}})");
  ASSERT_EQ(apply_config_json(text, "c.json", c), "");
  const json printed = config_to_json(c);  // each key where it was read (a value in another key's member shows)
  for (const auto& [key, value] : text["body_filter"].items()) EXPECT_EQ(printed["body_filter"][key], value) << key;
  EXPECT_FALSE(c.body_filter.enabled);
  EXPECT_DOUBLE_EQ(c.body_filter.rot_beta_per_rad_s, 0.25);
  EXPECT_EQ(validate_config(c), "");
  DaemonConfig back;
  ASSERT_EQ(apply_config_json(config_to_json(c), "printed", back), "");
  EXPECT_EQ(config_to_json(back), config_to_json(c));

  const auto error = [](const char* text) {
    DaemonConfig x;
    std::string e = apply_config_json(json::parse(text), "c.json", x);
    return e.empty() ? validate_config(x) : e;
  };
  std::string e = error(R"({"body_filter": {"cutoff": 1}})");
  EXPECT_NE(e.find("c.json: body_filter.cutoff: unknown key (expected enabled, min_cutoff_hz"), std::string::npos) << e;
  e = error(R"({"body_filter": 3})");
  EXPECT_NE(e.find("c.json: body_filter: expected an object"), std::string::npos) << e;
  e = error(R"({"body_filter": {"rot_min_cutoff_hz": 0}})");
  EXPECT_NE(e.find("body_filter rot_min_cutoff_hz must be > 0, not 0 (the \"body_filter\" keys: docs/daemon.md"),
            std::string::npos)
      << e;

  DaemonConfig f;
  const char* argv[] = {"bodyd", "--no-body-filter"};
  EXPECT_EQ(parse_command_line(2, argv, f).action, CliResult::Action::Run);
  EXPECT_FALSE(f.body_filter.enabled);
}

}  // namespace
}  // namespace bodyd::daemon
