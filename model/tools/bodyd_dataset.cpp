// bodyd-dataset: BVH clips -> training windows (.npy) + metadata (.json), using the runtime's feature code.
#include "bodyd/base/little_endian.h"
#include "bodyd/base/user_error.h"
#include "bodyd/inference/dataset.h"
#include "bodyd/motion/split_file.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <fstream>
#include <iostream>

using namespace bodyd;

namespace {

// .npy v1.0: magic, version, little-endian header length, a Python dict literal padded to 64 bytes.
void write_npy(const std::filesystem::path& path, const std::vector<float>& data, size_t n, size_t w, size_t d) {
  std::string header = fmt::format("{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}", n, w, d);
  const size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header += '\n';
  std::ofstream out(path, std::ios::binary);
  if (!out) throw UserError(path.string(), "cannot open for writing", "check that --out names a writable folder");
  const unsigned char magic[8] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0};
  out.write(reinterpret_cast<const char*>(magic), 8);
  const auto len = static_cast<uint16_t>(header.size());
  std::uint8_t len_le[2];
  store_le(len_le, len);
  out.write(reinterpret_cast<const char*>(len_le), 2);
  out.write(header.data(), static_cast<std::streamsize>(header.size()));
  out.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size() * sizeof(float)));
  if (!out) throw UserError(path.string(), "write failed", "check the free disk space");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bodyd-dataset: export training windows from BVH clips with bodyd's feature code"};
  std::vector<std::filesystem::path> splits;
  std::filesystem::path out_dir;
  std::vector<std::filesystem::path> bvh_files;
  std::string name = "train";
  int window = 20, stride = 2;
  app.add_option("--split", splits, "split file (paths relative to its folder's parent); may be given more than once "
                                    "(e.g. splits/train.txt and splits/train-extra.txt)");
  app.add_option("files", bvh_files, "BVH files (instead of or besides --split)");
  app.add_option("--out", out_dir, "output folder")->required();
  app.add_option("--name", name, "output base name: NAME.npy and NAME.json")->capture_default_str();
  app.add_option("--window", window, "frames per window")->capture_default_str()->check(CLI::Range(1, 512));
  app.add_option("--stride", stride, "frames between window ends")->capture_default_str()->check(CLI::Range(1, 1000));
  CLI11_PARSE(app, argc, argv);
  try {
    std::vector<std::filesystem::path> files = bvh_files;
    for (const auto& split : splits) {
      auto s = read_split(split);
      files.insert(files.end(), s.begin(), s.end());
    }
    if (files.empty()) throw UserError("", "no input", "give --split FILE or BVH files");
    std::filesystem::create_directories(out_dir);
    std::vector<float> data;
    size_t windows = 0, frames = 0;
    nlohmann::json skeleton_json;
    nlohmann::json clips = nlohmann::json::array();
    double fps = 0;
    for (const auto& f : files) {
      Motion m = read_bvh(f);
      if (std::string err = features::check_skeleton(m.skeleton); !err.empty())
        throw UserError(f.string(), err,
                        "export clips with the bodyd skeleton (docs/conventions.md, \"Skeleton and joint sets\")");
      if (fps == 0) {
        fps = m.fps();
        nlohmann::json offsets = nlohmann::json::array();
        for (const Vec3& o : m.skeleton.offsets) offsets.push_back({o.x(), o.y(), o.z()});
        // joint_Root's and Hips' offsets are overridden by position channels; the rest are shared by all files.
        skeleton_json = {{"names", m.skeleton.names}, {"parents", m.skeleton.parents}, {"offsets_m", offsets}};
      } else if (std::abs(m.fps() - fps) > 1e-3) {
        throw UserError(f.string(), fmt::format("{} fps differs from the first file's {} fps", m.fps(), fps),
                        "export every clip at one frame rate, or make one dataset per rate");
      }
      const int n = features::append_windows(features::clip_features(m), window, stride, data);
      clips.push_back({{"path", f.string()}, {"frames", m.frame_count()}, {"windows", n}});
      windows += static_cast<size_t>(n);
      frames += static_cast<size_t>(m.frame_count());
    }
    write_npy(out_dir / (name + ".npy"), data, windows, static_cast<size_t>(window), features::kDim);
    nlohmann::json trackers;
    for (Role r : kRoles) trackers[std::string(role_name(r))] = features::tracker_entries(r);
    // Where each body joint's position lives in a frame (for monitoring during training).
    nlohmann::json positions;
    for (int j = 1; j <= features::kBodyJoints; ++j) {
      const int o = features::joint_offset(j);
      positions[std::string(features::kJointNames[static_cast<size_t>(j)])] = {o, o + 1, o + 2};
    }
    nlohmann::json meta = {{"feature_version", features::kVersion},
                           {"joint_position_entries", positions},
                           {"dim", features::kDim},
                           {"window", window},
                           {"stride", stride},
                           {"fps", fps},
                           {"windows", windows},
                           {"frames", frames},
                           {"tracker_entries", trackers},
                           {"contact_entries", {features::kContactOffset, features::kContactOffset + 1}},
                           {"skeleton", skeleton_json},
                           {"clips", clips}};
    std::ofstream(out_dir / (name + ".json")) << meta.dump(1) << "\n";
    fmt::print("{} clips, {} frames -> {} windows of {}x{} in {}\n", files.size(), frames, windows, window,
               features::kDim, (out_dir / (name + ".npy")).string());
  } catch (const std::exception& e) {
    fmt::print(stderr, "bodyd-dataset: {}\n", e.what());
    return 1;
  }
  return 0;
}
