// Files the daemon keeps for itself (the mounting file): read with a size limit and without
// blocking (docs/reliability.md, "Persisted files"). Not for the reconstruction thread: it may
// wait on the disk.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>

namespace bodyd::daemon {

// The most a persisted file may hold (a mounting file is under 1 KiB).
inline constexpr std::size_t kMaxPersistedFileBytes = std::size_t{1} << 20;

// The whole of `path` when it is a regular file of at most `max_bytes`. nullopt with `error`
// empty when it does not exist; nullopt with `error` (the path and what is wrong) when it is
// not a regular file (a FIFO is refused, never waited on), is larger or cannot be read.
[[nodiscard]] std::optional<std::string> read_persisted_file(const std::filesystem::path& path, std::size_t max_bytes,
                                                             std::string& error);

}  // namespace bodyd::daemon
