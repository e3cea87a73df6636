// bodyd-render: pictures of reconstructions next to their ground truth (docs/render.md).
//
//   bodyd-render --truth CLIP.bvh --pred CLIP.pred.bvh --pred CLIP.ik.pred.bvh --out DIR
//
// writes DIR/<clip>.contact_sheet.png and DIR/<clip>.error_plot.png (and DIR/<clip>.anim.png with
// --apng). Exit 0 on success, 1 when an input is unusable (the message says which and why),
// 2 for a bad command line.
#include "bodyd/render/apng.h"
#include "bodyd/render/comparison.h"
#include "bodyd/render/draw.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <cstdio>
#include <fstream>

namespace {

void write_file(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) throw bodyd::render::RenderError(path.string(), "cannot write the file", "check the free disk space");
  fmt::print("wrote {} ({} bytes)\n", path.string(), bytes.size());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Draws a ground-truth clip and reconstructions of it: a contact sheet of stick figures (front and side "
               "views) and a plot of the per-frame error with the metrics (docs/render.md)."};
  std::filesystem::path truth_path, out_dir;
  std::vector<std::filesystem::path> preds, recordings;
  std::vector<std::string> labels;
  bodyd::render::SheetOptions sheet;
  bool apng = false;
  int anim_every = 1;
  app.add_option("--truth", truth_path, "ground-truth BVH clip")->required()->check(CLI::ExistingFile);
  app.add_option("--pred", preds, "a reconstruction of the clip as BVH (e.g. bodyd-eval --out-dir output); repeatable")
      ->check(CLI::ExistingFile);
  app.add_option("--recording", recordings,
                 "a pose recording (bodyd-record, docs/pose-recording.md) of the clip used as a prediction; repeatable")
      ->check(CLI::ExistingFile);
  app.add_option("--label", labels,
                 "legend label of each prediction, in order: the --pred files, then the --recording files (default: "
                 "the method from bodyd-eval's file name, else the file stem)");
  app.add_option("--out", out_dir, "output directory (created if missing)")->required();
  app.add_option("--every", sheet.every, "contact sheet: draw every Nth frame (default: about 12 frames over the clip)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--columns", sheet.columns, "contact sheet: frames per row")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_flag("--names", sheet.joint_names, "contact sheet: write joint names in the front views");
  app.add_flag("--apng", apng, "also write an animated PNG of the comparison, <clip>.anim.png");
  app.add_option("--anim-every", anim_every, "animation: use every Nth frame (played at the clip's speed)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  const size_t n_preds = preds.size() + recordings.size();
  if (n_preds == 0) {
    fmt::print(stderr, "bodyd-render: give at least one --pred or --recording\n");
    return 2;
  }
  if (labels.size() > n_preds) {
    fmt::print(stderr, "bodyd-render: {} --label for {} predictions\n", labels.size(), n_preds);
    return 2;
  }
  using bodyd::render::PredictionSource;
  std::vector<PredictionSource> sources;
  for (const auto& p : preds) sources.push_back({PredictionSource::Kind::kBvh, p, {}});
  for (const auto& p : recordings) sources.push_back({PredictionSource::Kind::kRecording, p, {}});
  for (size_t i = 0; i < labels.size(); ++i) sources[i].label = labels[i];
  try {
    const bodyd::render::Comparison cmp = bodyd::render::load_comparison(truth_path, sources);
    std::error_code ec;
    std::filesystem::create_directories(out_dir, ec);
    if (ec)
      throw bodyd::render::RenderError(out_dir.string(), fmt::format("cannot create the directory: {}", ec.message()),
                                       "check --out");
    write_file(out_dir / (cmp.clip_name + ".contact_sheet.png"), bodyd::render::contact_sheet_png(cmp, sheet));
    write_file(out_dir / (cmp.clip_name + ".error_plot.png"), bodyd::render::error_plot_png(cmp));
    if (apng) write_file(out_dir / (cmp.clip_name + ".anim.png"), bodyd::render::animation_apng(cmp, {anim_every}));
    for (const auto& m : cmp.methods) {
      fmt::print("{}: mpjpe_cm {:.2f} lower_pe_cm {:.2f} hand_pe_cm {:.2f} jitter_m_s3 {:.1f} foot_skate_ratio {:.3f}\n",
                 m.track.label, m.metrics.mpjpe_cm, m.metrics.lower_pe_cm, m.metrics.hand_pe_cm, m.metrics.jitter_m_s3,
                 m.metrics.foot_skate_ratio);
    }
  } catch (const std::exception& e) {
    fmt::print(stderr, "bodyd-render: {}\n", e.what());
    return 1;
  }
  return 0;
}
