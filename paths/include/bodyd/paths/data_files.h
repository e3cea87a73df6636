// Where bodyd's programs find their bundled files: the default model, the demo recording and
// skeleton, the viewer's page. Nothing is compiled in, so an installed or packaged bodyd, or a
// build tree moved elsewhere, finds its own files (docs/install.md, "Where bodyd finds its files").
//
// A file is named by its path relative to a data directory, the same in every layout:
// "models/bodyd-default.safetensors", "data/demo/walk.csv", "viewer/index.html". The data
// directories, searched in this order:
//
//   1. PREFIX/share/bodyd, where the running executable is PREFIX/bin/NAME (an install:
//      /usr/bin/bodyd -> /usr/share/bodyd);
//   2. $XDG_DATA_HOME/bodyd (default ~/.local/share/bodyd): files a user adds or replaces;
//   3. the source tree of the build the executable belongs to: the executable's directory or
//      one of its two parents holds the build's CMakeCache.txt, whose CMAKE_HOME_DIRECTORY
//      names the source tree (running from build/bin/ or build/tests/).
//
// Later directories are only looked at when the file is not in an earlier one.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::paths {

// The result of a search: the first existing file, or (not found) the first place it was
// looked for, so that messages can name where it belongs. `tried` lists every candidate path
// looked at, in order.
struct DataFile {
  std::filesystem::path path;
  bool found = false;
  std::vector<std::filesystem::path> tried;
};

// Searches for `relative` (e.g. "models/bodyd-default.safetensors") in the data directories.
[[nodiscard]] DataFile find_data_file(std::string_view relative);

// The same, with the executable's path and the environment given (for tests): `executable`
// as /proc/self/exe reads, `xdg_data_home` and `home` as the environment variables hold them
// (nullptr: unset).
[[nodiscard]] DataFile find_data_file(std::string_view relative, const std::filesystem::path& executable,
                                      const char* xdg_data_home, const char* home);

// "a, b or c": the tried paths of a search, for messages.
[[nodiscard]] std::string tried_text(const DataFile& file);

// The user's config file: $XDG_CONFIG_HOME/bodyd/config.json, by default
// ~/.config/bodyd/config.json (what `bodyd --user-config` and the systemd unit read, and where
// bodyd-ctl looks for the control endpoint). Empty when neither variable is set.
[[nodiscard]] std::filesystem::path user_config_file();
[[nodiscard]] std::filesystem::path user_config_file(const char* xdg_config_home, const char* home);

// A file of the user's state (kept across restarts, not configuration):
// $XDG_STATE_HOME/bodyd/NAME, by default ~/.local/state/bodyd/NAME. Empty when neither is set.
[[nodiscard]] std::filesystem::path user_state_file(std::string_view name);
[[nodiscard]] std::filesystem::path user_state_file(std::string_view name, const char* xdg_state_home, const char* home);

// The running executable's path (/proc/self/exe); empty if it cannot be read.
[[nodiscard]] std::filesystem::path executable_path();

// The source tree a build directory was configured from: CMAKE_HOME_DIRECTORY in
// `build_dir`/CMakeCache.txt; empty when there is none.
[[nodiscard]] std::filesystem::path source_tree_of_build(const std::filesystem::path& build_dir);

}  // namespace bodyd::paths
