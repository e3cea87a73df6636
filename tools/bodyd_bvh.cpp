// bodyd-bvh: what a BVH file holds (frames, frame rate, joints), for one or many files.
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/printable.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>

int main(int argc, char** argv) {
  CLI::App app{
      "Reads BVH files with bodyd's reader and prints, for each, its frame count, frame rate and joint count:\n"
      "  PATH: FRAMES frames, FPS fps, JOINTS joints\n"
      "or with --json one JSON array of {\"path\", \"frames\", \"fps\", \"joints\"} objects.\n"
      "Every file is read even if an earlier one is bad: good files are reported on stdout (bad ones\n"
      "are left out of the JSON array) and each bad file's error, 'bodyd-bvh: FILE:LINE: what', goes\n"
      "to stderr. Exit status: 0 if every file was read, 1 if any file was bad, 2 for bad arguments.",
      "bodyd-bvh"};
  std::vector<std::string> paths;
  bool json = false;
  app.add_option("files", paths, "BVH files")->required();
  app.add_flag("--json", json, "print a JSON array instead of one line per file");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help exits 0; every usage error exits 2 (CLI11's own codes vary by error).
    return app.exit(e) == 0 ? 0 : 2;
  }

  nlohmann::json out = nlohmann::json::array();
  int bad = 0;
  for (const std::string& path : paths) {
    try {
      std::error_code ec;
      if (std::filesystem::is_directory(path, ec)) throw bodyd::BvhError(path + ": is a directory, not a BVH file");
      const bodyd::Motion m = bodyd::read_bvh(path);
      if (json) {
        out.push_back({{"path", path}, {"frames", m.frame_count()}, {"fps", m.fps()}, {"joints", m.skeleton.size()}});
      } else {
        fmt::print("{}: {} frames, {:.6g} fps, {} joints\n", bodyd::printable(path, 4096), m.frame_count(), m.fps(),
                   m.skeleton.size());
        std::fflush(stdout);
      }
    } catch (const bodyd::BvhError& e) {
      ++bad;
      std::fflush(stdout);
      // The reader quotes file content escaped; escaping the whole message also covers a file
      // name with control characters (a terminal must never receive raw escape bytes).
      fmt::print(stderr, "bodyd-bvh: {}\n", bodyd::printable(e.what(), 4096));
    }
  }
  // A path that is not UTF-8 is written with U+FFFD (dump() would otherwise throw).
  if (json) fmt::print("{}\n", out.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
  return bad == 0 ? 0 : 1;
}
