// bodyd-bvh: what a BVH file holds (frames, frame rate, joints), for one or many files.
#include "bodyd/base/user_error.h"
#include "bodyd/inference/evaluation.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/printable.h"
#include "bodyd/motion/split_file.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>

int main(int argc, char** argv) {
  CLI::App app{
      "Reads BVH files with bodyd's reader and prints, for each, its frame count, frame rate and joint count:\n"
      "  PATH: FRAMES frames, FPS fps, JOINTS joints\n"
      "or with --json one JSON array of {\"path\", \"frames\", \"fps\", \"joints\"} objects.\n"
      "Every file is read even if an earlier one is bad: good files are reported on stdout (bad ones\n"
      "are left out of the JSON array) and each bad file's error, 'bodyd-bvh: FILE:LINE: what', goes\n"
      "to stderr. Exit status: 0 if every file was read, 1 if any file was bad, 2 for bad arguments.\n"
      "With --reference OUT.json it instead measures the body reference of the device mounting\n"
      "(docs/conventions.md, \"Device frames\") on the files and writes it to OUT.json:\n"
      "  bodyd-bvh --reference data/body-reference.json --split ../shared/data/bandai-namco/splits/train.txt",
      "bodyd-bvh"};
  std::vector<std::string> paths;
  bool json = false;
  std::string reference_out, split;
  app.add_option("files", paths, "BVH files");
  app.add_flag("--json", json, "print a JSON array instead of one line per file");
  app.add_option("--reference", reference_out, "measure the device-mounting body reference and write it to this file");
  app.add_option("--split", split, "split file (BVH paths relative to its folder's parent), besides or instead of files");
  try {
    app.parse(argc, argv);
    if (paths.empty() && split.empty()) throw CLI::RequiredError("files or --split");
  } catch (const CLI::ParseError& e) {
    // --help exits 0; every usage error exits 2 (CLI11's own codes vary by error).
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (!split.empty()) {
    try {
      for (const auto& p : bodyd::read_split(split)) paths.push_back(p.string());
    } catch (const std::exception& e) {
      fmt::print(stderr, "bodyd-bvh: {}\n", bodyd::printable(e.what(), 4096));
      return 2;
    }
  }
  if (!reference_out.empty()) {
    try {
      std::vector<bodyd::Motion> clips;
      for (const std::string& path : paths) clips.push_back(bodyd::read_bvh(path));
      const std::string provenance =
          split.empty() ? fmt::format("{} BVH files", paths.size())
                        : fmt::format("{} ({} clips)", std::filesystem::path(split).filename().string(), paths.size());
      const bodyd::BodyReference r = bodyd::measure_body_reference(clips, provenance);
      std::ofstream out(reference_out);
      out << bodyd::body_reference_json(r);
      if (!out) throw bodyd::UserError(reference_out, "cannot write", "check that the folder exists and is writable");
      fmt::print("{}: {} relaxed still standing frames from {} of {} clips; head pitch sd {:.2f} deg, roll sd {:.2f} "
                 "deg; wrists sd {:.2f} / {:.2f} deg\n",
                 reference_out, r.frames, r.clips, clips.size(), r.head_pitch_sd_deg, r.head_roll_sd_deg,
                 r.hand_sd_deg[0], r.hand_sd_deg[1]);
      return 0;
    } catch (const std::exception& e) {
      fmt::print(stderr, "bodyd-bvh: {}\n", bodyd::printable(e.what(), 4096));
      return 1;
    }
  }

  nlohmann::json out = nlohmann::json::array();
  int bad = 0;
  for (const std::string& path : paths) {
    try {
      std::error_code ec;
      if (std::filesystem::is_directory(path, ec)) throw bodyd::BvhError(path, "is a directory, not a BVH file");
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
