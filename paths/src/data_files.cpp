#include "bodyd/paths/data_files.h"

#include <cstdlib>
#include <fstream>
#include <optional>
#include <system_error>

namespace bodyd::paths {
namespace {

namespace fs = std::filesystem;

bool is_file(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

// The build directory holding `executable`: its directory or one of the two above it (bin/,
// tests/, tests/<area>/) with a CMakeCache.txt. Looks no higher, so an installed program never
// wanders through unrelated directories.
std::optional<fs::path> build_dir_of(const fs::path& executable) {
  fs::path dir = executable.parent_path();
  for (int up = 0; up < 3 && !dir.empty(); ++up, dir = dir.parent_path()) {
    if (is_file(dir / "CMakeCache.txt")) return dir;
    if (dir == dir.root_path()) break;
  }
  return std::nullopt;
}

}  // namespace

fs::path executable_path() {
  std::error_code ec;
  fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : p;
}

fs::path source_tree_of_build(const fs::path& build_dir) {
  std::ifstream in(build_dir / "CMakeCache.txt");
  std::string line;
  constexpr std::string_view kKey = "CMAKE_HOME_DIRECTORY:INTERNAL=";
  while (std::getline(in, line)) {
    if (line.rfind(kKey, 0) == 0) return fs::path(line.substr(kKey.size()));
  }
  return {};
}

DataFile find_data_file(std::string_view relative, const fs::path& executable, const char* xdg_data_home,
                        const char* home) {
  DataFile result;
  auto try_dir = [&](const fs::path& dir) {
    if (dir.empty()) return false;
    const fs::path candidate = dir / fs::path(relative);
    result.tried.push_back(candidate);
    if (!is_file(candidate)) return false;
    result.path = candidate;
    result.found = true;
    return true;
  };
  // 1. PREFIX/share/bodyd next to PREFIX/bin/NAME.
  if (!executable.empty() && try_dir(executable.parent_path().parent_path() / "share" / "bodyd")) return result;
  // 2. $XDG_DATA_HOME/bodyd, or ~/.local/share/bodyd (XDG Base Directory: an unset or
  //    relative value means the default).
  fs::path xdg;
  if (xdg_data_home && *xdg_data_home && fs::path(xdg_data_home).is_absolute()) xdg = xdg_data_home;
  else if (home && *home) xdg = fs::path(home) / ".local" / "share";
  if (!xdg.empty() && try_dir(xdg / "bodyd")) return result;
  // 3. The source tree, when running from a build.
  if (!executable.empty()) {
    if (auto build = build_dir_of(executable)) {
      if (try_dir(source_tree_of_build(*build))) return result;
    }
  }
  if (!result.tried.empty()) result.path = result.tried.front();
  else result.path = fs::path(relative);
  return result;
}

DataFile find_data_file(std::string_view relative) {
  return find_data_file(relative, executable_path(), std::getenv("XDG_DATA_HOME"), std::getenv("HOME"));
}

fs::path user_config_file(const char* xdg_config_home, const char* home) {
  // XDG Base Directory: an unset, empty or relative value means the default.
  if (xdg_config_home && *xdg_config_home && fs::path(xdg_config_home).is_absolute())
    return fs::path(xdg_config_home) / "bodyd" / "config.json";
  if (home && *home) return fs::path(home) / ".config" / "bodyd" / "config.json";
  return {};
}

fs::path user_config_file() { return user_config_file(std::getenv("XDG_CONFIG_HOME"), std::getenv("HOME")); }

fs::path user_state_file(std::string_view name, const char* xdg_state_home, const char* home) {
  if (xdg_state_home && *xdg_state_home && fs::path(xdg_state_home).is_absolute())
    return fs::path(xdg_state_home) / "bodyd" / name;
  if (home && *home) return fs::path(home) / ".local" / "state" / "bodyd" / name;
  return {};
}

fs::path user_state_file(std::string_view name) {
  return user_state_file(name, std::getenv("XDG_STATE_HOME"), std::getenv("HOME"));
}

std::string tried_text(const DataFile& file) {
  std::string text;
  for (std::size_t i = 0; i < file.tried.size(); ++i) {
    if (i > 0) text += i + 1 == file.tried.size() ? " or " : ", ";
    text += file.tried[i].string();
  }
  return text;
}

}  // namespace bodyd::paths
