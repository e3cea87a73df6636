// Split files: the lists of motion-capture clips that training (bodyd-dataset), the evaluation
// (bodyd-eval, bodyd-bvh) and the tests read, e.g. bandai-namco/splits/val.txt. One reader, so
// every program sees the same clips in a file (docs/evaluation.md, "Split files"):
//
//   - one path per line, relative to the parent of the split file's folder (splits/val.txt lists
//     dataset-1/... relative to the dataset root); an absolute path is taken as it is;
//   - spaces, tabs and carriage returns at either end of a line are not part of the path (a file
//     written on Windows, CRLF, reads the same);
//   - a line that is then empty, or starts with '#', is skipped ('#' later in a line is part of the path);
//   - every listed file must exist, and a split must list at least one.
//
// training/train.py's read_clip_list reads its clip lists (--exclude-split) by the same line rule.
#pragma once

#include "bodyd/base/user_error.h"

#include <filesystem>
#include <string_view>
#include <vector>

namespace bodyd {

// The clips of a split file, in its order. Throws UserError (base/user_error.h) naming the file
// (and the line) when it cannot be opened, lists a file that does not exist, or lists none.
[[nodiscard]] std::vector<std::filesystem::path> read_split(const std::filesystem::path& split_file);

// One line of a split file by the rule above: the path it lists, or "" for a skipped line.
[[nodiscard]] std::string_view split_line_path(std::string_view line);

}  // namespace bodyd
