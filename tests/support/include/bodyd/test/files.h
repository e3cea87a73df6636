// Whole files in and out, for tests. A file that cannot be read reads as empty (a test then
// fails on its content, saying what it expected).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::test {

[[nodiscard]] std::string read_file(const std::filesystem::path& path);
[[nodiscard]] std::vector<std::uint8_t> read_file_bytes(const std::filesystem::path& path);
// Writes `content` to `path` (replacing it); false when the file cannot be written.
bool write_file(const std::filesystem::path& path, std::string_view content);
// The sample lines of the tracker log at `path` as it is on disk now (neither comments nor the
// column header): what a kill -9 of its writer would leave.
[[nodiscard]] std::size_t samples_on_disk(const std::filesystem::path& path);

}  // namespace bodyd::test
