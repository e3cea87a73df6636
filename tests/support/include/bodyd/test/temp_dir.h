// A fresh private temporary directory (mkdtemp under the temp directory), removed with
// everything in it at destruction.
#pragma once

#include <filesystem>
#include <string>

namespace bodyd::test {

struct TempDir {
  // <temp>/<stem>-XXXXXX. Throws std::runtime_error when no directory can be made.
  explicit TempDir(const std::string& stem = "bodyd-test");
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  std::filesystem::path path;
};

}  // namespace bodyd::test
