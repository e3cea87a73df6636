// Files the daemon keeps for itself (the mounting file; the endpoints file it writes at start):
// read with a size limit and without blocking, written through a private temporary file
// (docs/reliability.md, "Persisted files"). Neither is for the reconstruction thread: both may
// wait on the disk.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <sys/types.h>

namespace bodyd::daemon {

// The most a persisted file may hold (a mounting file is under 1 KiB).
inline constexpr std::size_t kMaxPersistedFileBytes = std::size_t{1} << 20;

// The whole of `path` when it is a regular file of at most `max_bytes`. nullopt with `error`
// empty when it does not exist; nullopt with `error` (the path and what is wrong) when it is
// not a regular file (a FIFO is refused, never waited on), is larger or cannot be read.
[[nodiscard]] std::optional<std::string> read_persisted_file(const std::filesystem::path& path, std::size_t max_bytes,
                                                             std::string& error);

// Creates `dir` and every missing folder above it with mode 0700 (the XDG Base Directory rule
// for $XDG_STATE_HOME: the user's state is for the user alone); folders that exist are left as
// they are. Empty on success, otherwise the folder and the reason.
[[nodiscard]] std::string create_private_directories(const std::filesystem::path& dir);

// Replaces `path` by `text` with permissions `mode`, creating its folder: the text goes to a new
// file of a unique name beside it (mkostemp: O_CREAT | O_EXCL, mode 0600, so nothing already
// there, a symbolic link or a FIFO, is followed or opened), is flushed to the disk (fsync) and
// renamed over `path`. Empty on success, otherwise what went wrong (the path, the reason); the
// temporary file is then removed.
[[nodiscard]] std::string replace_persisted_file(const std::filesystem::path& path, std::string_view text, mode_t mode);

}  // namespace bodyd::daemon
