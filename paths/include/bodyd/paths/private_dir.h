// Whether a directory is fit to hold this user's sockets: a directory (not a symbolic link),
// owned by this user, with no access for others (mode 0700 or stricter). Used by the daemon's
// ipc:// endpoints and the SlimeVR bridges' sockets, each adding what to do.
#pragma once

#include <filesystem>
#include <string>

namespace bodyd::paths {

// Empty when `dir` is private; otherwise what is wrong with it, e.g.
// "/tmp/bodyd is open to other users (mode 0755)" or "/tmp/x: No such file or directory".
[[nodiscard]] std::string private_directory_problem(const std::filesystem::path& dir);

}  // namespace bodyd::paths
