#include "bodyd/motion/split_file.h"

#include "bodyd/base/user_error.h"

#include <fmt/format.h>

#include <fstream>
#include <string>

namespace bodyd {

std::string_view split_line_path(std::string_view line) {
  constexpr std::string_view kBlank = " \t\r";
  const auto begin = line.find_first_not_of(kBlank);
  if (begin == std::string_view::npos || line[begin] == '#') return {};
  const auto end = line.find_last_not_of(kBlank);
  return line.substr(begin, end - begin + 1);
}

std::vector<std::filesystem::path> read_split(const std::filesystem::path& split_file) {
  std::ifstream in(split_file);
  if (!in)
    throw UserError(split_file.string(), "cannot open the split file",
                    "check the path (docs/evaluation.md, \"Split files\")");
  const std::filesystem::path base = split_file.parent_path().parent_path();
  std::vector<std::filesystem::path> paths;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const std::string_view listed = split_line_path(line);
    if (listed.empty()) continue;
    const std::filesystem::path p = base / listed;
    if (!std::filesystem::exists(p))
      throw UserError(fmt::format("{}:{}", split_file.string(), line_no),
                      fmt::format("'{}' does not exist (paths are relative to {})", p.string(), base.string()),
                      "fix the line or restore the clip");
    paths.push_back(p);
  }
  if (in.bad()) throw UserError(split_file.string(), "read error");
  if (paths.empty())
    throw UserError(split_file.string(), "the split lists no files",
                    "list one clip path per line (docs/evaluation.md, \"Split files\")");
  return paths;
}

}  // namespace bodyd
