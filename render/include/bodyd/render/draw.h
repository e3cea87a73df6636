// Pictures of a Comparison, drawn with cairo (2D vector drawing, antialiased, written as PNG by
// cairo's libpng writer). Every function returns the PNG file's bytes; for the same inputs (and
// the same cairo, fontconfig and fonts) the bytes are the same: nothing depends on the clock,
// the locale or memory addresses. Layout and colours: docs/render.md.
#pragma once

#include "bodyd/render/comparison.h"

#include <cstdint>
#include <vector>

namespace bodyd::render {

struct ImageSize {
  int width = 0;
  int height = 0;
};

struct SheetOptions {
  int every = 0;         // draw frames 0, every, 2*every, ...; 0: about kAutoPanels frames over the clip
  int columns = 6;       // frames per row of the sheet, >= 1 (else a bug)
  bool joint_names = false;  // write the truth's joint names in the front views
};
inline constexpr int kAutoPanels = 12;

// The frame stride a sheet uses for `frame_count` frames (options.every, or the automatic one).
[[nodiscard]] int sheet_stride(int frame_count, const SheetOptions& options);
// The frames a sheet shows.
[[nodiscard]] std::vector<int> sheet_frames(int frame_count, const SheetOptions& options);
[[nodiscard]] ImageSize contact_sheet_size(const Comparison& comparison, const SheetOptions& options);

// The contact sheet: for each shown frame a front view (facing the truth's pelvis) and a side
// view (the truth facing right), centred on the truth's Hips, floor line at y = 0; the truth in
// dark grey and each method in its colour on top; red rings on the truth's Head, Hand_L, Hand_R
// (the tracked joints); a title with the clip name and a legend.
[[nodiscard]] std::vector<std::uint8_t> contact_sheet_png(const Comparison& comparison, const SheetOptions& options);

inline constexpr ImageSize kErrorPlotSize{1200, 860};
// Per-frame error over time, three panels (all 21 joints, lower body, hands), one line per method,
// with the clip name and each method's metrics (and the truth's jitter and foot skating) on top.
[[nodiscard]] std::vector<std::uint8_t> error_plot_png(const Comparison& comparison);

struct AnimationOptions {
  int every = 1;  // animate frames 0, every, 2*every, ... at the clip's speed; >= 1 (else a bug)
};
inline constexpr ImageSize kAnimationFrameSize{560, 400};
// One frame of the animation (front and side views of frame `frame`, legend, per-frame errors);
// `frame` in [0, frame_count) (else a bug).
[[nodiscard]] std::vector<std::uint8_t> animation_frame_png(const Comparison& comparison, int frame);
// The animation as an animated PNG (APNG, looping): frames drawn by animation_frame_png().
[[nodiscard]] std::vector<std::uint8_t> animation_apng(const Comparison& comparison, const AnimationOptions& options);

// The colour of method i in every picture (truth: kTruthColour), RGB in [0, 1].
struct Rgb {
  double r, g, b;
};
inline constexpr Rgb kTruthColour{0.20, 0.20, 0.20};
inline constexpr Rgb kTrackedColour{0.84, 0.15, 0.16};
[[nodiscard]] Rgb method_colour(int index);

}  // namespace bodyd::render
