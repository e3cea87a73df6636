// Paths the tests use. Tests needing ../shared/data call GTEST_SKIP() when it is absent.
#pragma once
#include <filesystem>

namespace bodyd::test {
inline std::filesystem::path shared_data() { return BODYD_SHARED_DATA_DIR; }
inline std::filesystem::path bandai() { return shared_data() / "bandai-namco"; }
inline bool have_bandai() { return std::filesystem::exists(bandai() / "splits" / "val.txt"); }
inline std::filesystem::path fixtures() { return BODYD_TEST_DATA_DIR; }
inline std::filesystem::path bin_dir() { return BODYD_BIN_DIR; }
inline std::filesystem::path source_dir() { return BODYD_SOURCE_DIR; }
}  // namespace bodyd::test
