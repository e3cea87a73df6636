#include "bodyd/render/draw.h"

#include "bodyd/base/require.h"
#include "bodyd/render/apng.h"

#include <cairo.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>

namespace bodyd::render {
namespace {

constexpr const char* kFont = "DejaVu Sans";

// ---- cairo plumbing ------------------------------------------------------------------------

struct SurfaceDeleter {
  void operator()(cairo_surface_t* s) const { cairo_surface_destroy(s); }
};
struct ContextDeleter {
  void operator()(cairo_t* c) const { cairo_destroy(c); }
};

// An opaque white canvas of the given size.
class Canvas {
 public:
  Canvas(int width, int height)
      : surface_(cairo_image_surface_create(CAIRO_FORMAT_RGB24, width, height)), cr_(cairo_create(surface_.get())) {
    if (cairo_status(cr_.get()) != CAIRO_STATUS_SUCCESS) {
      throw RenderError("cairo", fmt::format("cannot create a {}x{} image: {}", width, height,
                                             cairo_status_to_string(cairo_status(cr_.get()))));
    }
    // Fixed font options, so text does not depend on the desktop's settings.
    cairo_font_options_t* fo = cairo_font_options_create();
    cairo_font_options_set_antialias(fo, CAIRO_ANTIALIAS_GRAY);
    cairo_font_options_set_hint_style(fo, CAIRO_HINT_STYLE_NONE);
    cairo_font_options_set_hint_metrics(fo, CAIRO_HINT_METRICS_OFF);
    cairo_set_font_options(cr_.get(), fo);
    cairo_font_options_destroy(fo);
    cairo_select_font_face(cr_.get(), kFont, CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
    cairo_set_source_rgb(cr_.get(), 1, 1, 1);
    cairo_paint(cr_.get());
  }
  cairo_t* cr() { return cr_.get(); }

  std::vector<std::uint8_t> png() {
    cairo_surface_flush(surface_.get());
    std::vector<std::uint8_t> out;
    const cairo_status_t status = cairo_surface_write_to_png_stream(
        surface_.get(),
        [](void* closure, const unsigned char* data, unsigned int length) {
          auto* v = static_cast<std::vector<std::uint8_t>*>(closure);
          v->insert(v->end(), data, data + length);
          return CAIRO_STATUS_SUCCESS;
        },
        &out);
    if (status != CAIRO_STATUS_SUCCESS) {
      throw RenderError("cairo", fmt::format("cannot encode PNG: {}", cairo_status_to_string(status)));
    }
    return out;
  }

 private:
  std::unique_ptr<cairo_surface_t, SurfaceDeleter> surface_;
  std::unique_ptr<cairo_t, ContextDeleter> cr_;
};

void set_colour(cairo_t* cr, const Rgb& c, double alpha = 1.0) { cairo_set_source_rgba(cr, c.r, c.g, c.b, alpha); }

enum class Align { kLeft, kCentre, kRight };

void text(cairo_t* cr, double x, double y, double size, const std::string& s, Align align = Align::kLeft,
          bool bold = false) {
  cairo_select_font_face(cr, kFont, CAIRO_FONT_SLANT_NORMAL, bold ? CAIRO_FONT_WEIGHT_BOLD : CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, size);
  double dx = 0.0;
  if (align != Align::kLeft) {
    cairo_text_extents_t ext;
    cairo_text_extents(cr, s.c_str(), &ext);
    dx = align == Align::kCentre ? -ext.x_advance / 2 : -ext.x_advance;
  }
  cairo_move_to(cr, x + dx, y);
  cairo_show_text(cr, s.c_str());
}

std::string number(double v, int decimals) {
  if (std::isnan(v)) return "n/a";
  return fmt::format("{:.{}f}", v, decimals);
}

// ---- geometry ------------------------------------------------------------------------------

// Indices of the joints a picture uses, found once per comparison.
struct Joints {
  JointSets sets;
  std::vector<bool> body;  // the 21 body joints
  int hips = -1, head = -1, hand_l = -1, hand_r = -1, leg_l = -1, leg_r = -1;
  explicit Joints(const Skeleton& s) : sets(joint_sets(s)), body(static_cast<size_t>(s.size()), false) {
    for (int j : sets.all) body[static_cast<size_t>(j)] = true;
    hips = s.find("Hips");
    head = s.find("Head");
    hand_l = s.find("Hand_L");
    hand_r = s.find("Hand_R");
    leg_l = s.find("UpperLeg_L");
    leg_r = s.find("UpperLeg_R");
  }
};

// An orthographic view of one frame: horizontal axis `axis` (unit, in the floor plane) through
// the truth's Hips, +Y up, floor at y = 0.
struct View {
  Vec3 centre;      // truth's Hips, y ignored
  Vec3 axis;        // world direction drawn to the right
  double x0, y0;    // pixel position of (centre, y = 0)
  double px_per_m;
  [[nodiscard]] std::array<double, 2> project(const Vec3& p) const {
    return {x0 + (p - centre).dot(axis) * px_per_m, y0 - p.y() * px_per_m};
  }
};

// The truth's left (from the right hip to the left hip) and forward directions in the floor
// plane, at one frame. forward = left x up, so a body facing +Z has left = +X.
void body_axes(const Joints& jn, const GlobalPose& truth, Vec3& left, Vec3& forward) {
  left = truth.positions[static_cast<size_t>(jn.leg_l)] - truth.positions[static_cast<size_t>(jn.leg_r)];
  left.y() = 0.0;
  if (left.norm() < 1e-6) left = Vec3::UnitX();
  left.normalize();
  forward = left.cross(Vec3::UnitY());
}

void draw_skeleton(cairo_t* cr, const Skeleton& skel, const Joints& jn, const GlobalPose& pose, const View& view,
                   const Rgb& colour, double width, double alpha) {
  set_colour(cr, colour, alpha);
  cairo_set_line_width(cr, width);
  cairo_set_line_cap(cr, CAIRO_LINE_CAP_ROUND);
  cairo_set_line_join(cr, CAIRO_LINE_JOIN_ROUND);
  for (int j = 0; j < skel.size(); ++j) {
    const int p = skel.parents[static_cast<size_t>(j)];
    if (p < 0 || !jn.body[static_cast<size_t>(j)] || !jn.body[static_cast<size_t>(p)]) continue;
    const auto a = view.project(pose.positions[static_cast<size_t>(p)]);
    const auto b = view.project(pose.positions[static_cast<size_t>(j)]);
    cairo_move_to(cr, a[0], a[1]);
    cairo_line_to(cr, b[0], b[1]);
  }
  cairo_stroke(cr);
  for (int j : jn.sets.all) {
    const auto a = view.project(pose.positions[static_cast<size_t>(j)]);
    cairo_arc(cr, a[0], a[1], width * 0.9, 0, 2 * M_PI);
    cairo_fill(cr);
  }
}

// Both views of one frame in the rectangle (x, y, w, h): front on the left, side on the right.
void draw_frame_views(cairo_t* cr, const Comparison& cmp, const Joints& jn, int frame, double x, double y, double w,
                      double h, double px_per_m, bool joint_names) {
  const GlobalPose& truth = cmp.truth.frames[static_cast<size_t>(frame)];
  Vec3 left, forward;
  body_axes(jn, truth, left, forward);
  Vec3 centre = truth.positions[static_cast<size_t>(jn.hips)];
  centre.y() = 0.0;
  const double view_w = w / 2;
  const double floor_y = y + h - 14;
  for (int v = 0; v < 2; ++v) {
    const double vx = x + v * view_w;
    // Front: looking at the truth's front, its left on our right. Side: the truth faces right.
    const View view{centre, v == 0 ? left : forward, vx + view_w / 2, floor_y, px_per_m};
    cairo_save(cr);
    cairo_rectangle(cr, vx, y, view_w, h);
    cairo_clip(cr);
    cairo_set_source_rgb(cr, 0.55, 0.55, 0.55);
    cairo_set_line_width(cr, 1.0);
    cairo_move_to(cr, vx + 4, floor_y);
    cairo_line_to(cr, vx + view_w - 4, floor_y);
    cairo_stroke(cr);
    draw_skeleton(cr, cmp.skeleton, jn, truth, view, kTruthColour, 3.0, 0.85);
    for (size_t m = 0; m < cmp.methods.size(); ++m) {
      draw_skeleton(cr, cmp.skeleton, jn, cmp.methods[m].track.frames[static_cast<size_t>(frame)], view,
                    method_colour(static_cast<int>(m)), 2.0, 0.9);
    }
    set_colour(cr, kTrackedColour);
    cairo_set_line_width(cr, 1.5);
    for (int j : {jn.head, jn.hand_l, jn.hand_r}) {
      const auto a = view.project(truth.positions[static_cast<size_t>(j)]);
      cairo_new_sub_path(cr);
      cairo_arc(cr, a[0], a[1], 5.5, 0, 2 * M_PI);
    }
    cairo_stroke(cr);
    if (joint_names && v == 0) {
      cairo_set_source_rgb(cr, 0.1, 0.1, 0.5);
      for (int j : jn.sets.all) {
        const auto a = view.project(truth.positions[static_cast<size_t>(j)]);
        text(cr, a[0] + 4, a[1] - 2, 7.0, cmp.skeleton.names[static_cast<size_t>(j)]);
      }
    }
    cairo_set_source_rgb(cr, 0.45, 0.45, 0.45);
    text(cr, vx + 4, floor_y + 11, 9.0, v == 0 ? "front" : "side");
    cairo_restore(cr);
  }
  cairo_set_source_rgb(cr, 0.85, 0.85, 0.85);
  cairo_set_line_width(cr, 1.0);
  cairo_move_to(cr, x + view_w + 0.5, y + 4);
  cairo_line_to(cr, x + view_w + 0.5, y + h - 4);
  cairo_stroke(cr);
}

// Pixels per metre so that the highest joint of any track (at least 1.2 m) fits in `height` px.
double fit_scale(const Comparison& cmp, const Joints& jn, double height) {
  double top = 1.2;
  auto scan = [&](const Track& t) {
    for (const GlobalPose& g : t.frames) {
      for (int j : jn.sets.all) top = std::max(top, g.positions[static_cast<size_t>(j)].y());
    }
  };
  scan(cmp.truth);
  for (const MethodResult& m : cmp.methods) scan(m.track);
  return height / (std::min(top, 3.0) + 0.12);
}

// Legend entries in one row from (x, y): truth, each method, tracked joints. Returns the end x.
double draw_legend(cairo_t* cr, const Comparison& cmp, double x, double y, double size) {
  auto entry = [&](const Rgb& c, const std::string& label, double width) {
    set_colour(cr, c);
    cairo_set_line_width(cr, width);
    cairo_move_to(cr, x, y - size * 0.35);
    cairo_line_to(cr, x + 22, y - size * 0.35);
    cairo_stroke(cr);
    cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
    text(cr, x + 27, y, size, label);
    cairo_text_extents_t ext;
    cairo_text_extents(cr, label.c_str(), &ext);
    x += 27 + ext.x_advance + 18;
  };
  entry(kTruthColour, "ground truth", 3.0);
  for (size_t m = 0; m < cmp.methods.size(); ++m) entry(method_colour(static_cast<int>(m)), cmp.methods[m].track.label, 2.0);
  set_colour(cr, kTrackedColour);
  cairo_set_line_width(cr, 1.5);
  cairo_new_sub_path(cr);
  cairo_arc(cr, x + 6, y - size * 0.35, 5.5, 0, 2 * M_PI);
  cairo_stroke(cr);
  cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
  const std::string tracked = "tracked head and hands (truth)";
  text(cr, x + 17, y, size, tracked);
  cairo_text_extents_t ext;
  cairo_text_extents(cr, tracked.c_str(), &ext);
  return x + 17 + ext.x_advance;
}

// Contact sheet geometry.
constexpr double kCellW = 300, kCellH = 262, kCellLabelH = 18, kSheetTitleH = 62, kMargin = 10;

// "a, b" nice round step for an axis of range [0, max] with about `ticks` ticks.
double nice_step(double max, int ticks) {
  const double raw = max / ticks;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 2.5, 5.0, 10.0}) {
    if (raw <= m * mag) return m * mag;
  }
  return 10.0 * mag;
}

// Decimals that print every multiple of `step` exactly (1, 0.5, 0.25 -> 0, 1, 2).
int decimals_for(double step) {
  for (int d = 0; d < 3; ++d) {
    const double scaled = step * std::pow(10.0, d);
    if (std::abs(scaled - std::round(scaled)) < 1e-9) return d;
  }
  return 3;
}

}  // namespace

Rgb method_colour(int index) {
  // Tableau 10 without its red (red marks the tracked joints).
  static constexpr std::array<Rgb, 8> kPalette{{{0.12, 0.47, 0.71},
                                                {1.00, 0.50, 0.05},
                                                {0.17, 0.63, 0.17},
                                                {0.58, 0.40, 0.74},
                                                {0.55, 0.34, 0.29},
                                                {0.89, 0.47, 0.76},
                                                {0.74, 0.74, 0.13},
                                                {0.09, 0.75, 0.81}}};
  return kPalette[static_cast<size_t>(index) % kPalette.size()];
}

int sheet_stride(int frame_count, const SheetOptions& options) {
  if (options.every > 0) return options.every;
  return std::max(1, (frame_count + kAutoPanels - 1) / kAutoPanels);
}

std::vector<int> sheet_frames(int frame_count, const SheetOptions& options) {
  std::vector<int> frames;
  const int stride = sheet_stride(frame_count, options);
  for (int f = 0; f < frame_count; f += stride) frames.push_back(f);
  return frames;
}

ImageSize contact_sheet_size(const Comparison& cmp, const SheetOptions& options) {
  const int panels = static_cast<int>(sheet_frames(cmp.frame_count(), options).size());
  const int columns = std::clamp(options.columns, 1, std::max(1, panels));
  const int rows = (panels + columns - 1) / columns;
  return {static_cast<int>(2 * kMargin + columns * kCellW),
          static_cast<int>(kSheetTitleH + rows * (kCellH + kCellLabelH) + kMargin)};
}

std::vector<std::uint8_t> contact_sheet_png(const Comparison& cmp, const SheetOptions& options) {
  // bodyd-render's --columns is checked where it is parsed.
  BODYD_REQUIRE(options.columns >= 1, "contact sheet: columns must be at least 1");
  const Joints jn(cmp.skeleton);
  const std::vector<int> frames = sheet_frames(cmp.frame_count(), options);
  const ImageSize size = contact_sheet_size(cmp, options);
  const int columns = std::clamp(options.columns, 1, std::max(1, static_cast<int>(frames.size())));
  Canvas canvas(size.width, size.height);
  cairo_t* cr = canvas.cr();

  cairo_set_source_rgb(cr, 0.05, 0.05, 0.05);
  text(cr, kMargin, 24, 17, cmp.clip_name, Align::kLeft, true);
  cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
  text(cr, size.width - kMargin, 24, 12,
       fmt::format("every {} frames of {} at {} fps", sheet_stride(cmp.frame_count(), options), cmp.frame_count(),
                   number(cmp.fps, 0)),
       Align::kRight);
  draw_legend(cr, cmp, kMargin, 50, 12);

  const double px_per_m = fit_scale(cmp, jn, kCellH - 22);
  for (size_t i = 0; i < frames.size(); ++i) {
    const double x = kMargin + static_cast<double>(i % static_cast<size_t>(columns)) * kCellW;
    const double y = kSheetTitleH + static_cast<double>(i / static_cast<size_t>(columns)) * (kCellH + kCellLabelH);
    cairo_set_source_rgb(cr, 0.96, 0.96, 0.96);
    cairo_rectangle(cr, x + 2, y, kCellW - 4, kCellLabelH + kCellH - 4);
    cairo_fill(cr);
    cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
    text(cr, x + 8, y + 13, 11, fmt::format("frame {}  ({} s)", frames[i], number(frames[i] / cmp.fps, 2)));
    draw_frame_views(cr, cmp, jn, frames[i], x + 2, y + kCellLabelH, kCellW - 4, kCellH - 4, px_per_m,
                     options.joint_names);
  }
  return canvas.png();
}

std::vector<std::uint8_t> error_plot_png(const Comparison& cmp) {
  const ImageSize size = kErrorPlotSize;
  Canvas canvas(size.width, size.height);
  cairo_t* cr = canvas.cr();
  const double left = 70, right = size.width - 20;

  cairo_set_source_rgb(cr, 0.05, 0.05, 0.05);
  text(cr, left, 26, 17, cmp.clip_name + ": per-frame error against the ground truth", Align::kLeft, true);
  double y = 50;
  for (size_t m = 0; m < cmp.methods.size(); ++m) {
    const AccuracyMetrics& a = cmp.methods[m].metrics;
    set_colour(cr, method_colour(static_cast<int>(m)));
    cairo_rectangle(cr, left, y - 10, 12, 12);
    cairo_fill(cr);
    cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
    text(cr, left + 18, y,
         12, fmt::format("{}:  mpjpe_cm {}   lower_pe_cm {}   hand_pe_cm {}   jitter_m_s3 {}   foot_skate_ratio {}",
                         cmp.methods[m].track.label, number(a.mpjpe_cm, 2), number(a.lower_pe_cm, 2),
                         number(a.hand_pe_cm, 2), number(a.jitter_m_s3, 1), number(a.foot_skate_ratio, 3)));
    y += 19;
  }
  set_colour(cr, kTruthColour);
  cairo_rectangle(cr, left, y - 10, 12, 12);
  cairo_fill(cr);
  cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
  text(cr, left + 18, y, 12,
       fmt::format("ground truth:  jitter_m_s3 {}   foot_skate_ratio {}    ({} frames at {} fps)",
                   number(cmp.truth_quality.jitter_m_s3, 1), number(cmp.truth_quality.foot_skate_ratio, 3),
                   cmp.frame_count(), number(cmp.fps, 0)));
  y += 16;

  struct Panel {
    const char* title;
    std::vector<double> FrameErrors::*series;
  };
  const std::array<Panel, 3> panels{{{"all 21 joints", &FrameErrors::all_cm},
                                     {"lower body (9 joints)", &FrameErrors::lower_cm},
                                     {"hands (Hand_L, Hand_R)", &FrameErrors::hands_cm}}};
  const double top = std::max(y + 10, 130.0);
  const double gap = 46;
  const double panel_h = (size.height - top - 40 - 2 * gap) / 3;
  const int n = cmp.frame_count();
  const double duration_s = std::max(1, n - 1) / cmp.fps;
  const double t_step = nice_step(duration_s, 10);
  for (size_t p = 0; p < panels.size(); ++p) {
    const double py = top + static_cast<double>(p) * (panel_h + gap);
    double ymax = 0.0;
    for (const MethodResult& m : cmp.methods) {
      for (double v : m.errors.*panels[p].series) {
        if (std::isfinite(v)) ymax = std::max(ymax, v);
      }
    }
    ymax = std::max(ymax, 1.0);
    const double y_step = nice_step(ymax, 4);
    ymax = std::ceil(ymax / y_step - 1e-9) * y_step;
    auto px = [&](double t_s) { return left + (right - left) * t_s / duration_s; };
    auto py_of = [&](double v) { return py + panel_h - panel_h * v / ymax; };

    cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
    text(cr, left, py - 8, 13, fmt::format("{} — mean joint error (cm)", panels[p].title), Align::kLeft, true);
    cairo_set_line_width(cr, 1.0);
    for (double v = 0.0; v <= ymax + 1e-9; v += y_step) {
      const double yy = std::round(py_of(v)) + 0.5;
      cairo_set_source_rgb(cr, 0.88, 0.88, 0.88);
      cairo_move_to(cr, left, yy);
      cairo_line_to(cr, right, yy);
      cairo_stroke(cr);
      cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
      text(cr, left - 6, yy + 4, 11, number(v, decimals_for(y_step)), Align::kRight);
    }
    for (double t = 0.0; t <= duration_s + 1e-9; t += t_step) {
      const double xx = std::round(px(t)) + 0.5;
      cairo_set_source_rgb(cr, 0.92, 0.92, 0.92);
      cairo_move_to(cr, xx, py);
      cairo_line_to(cr, xx, py + panel_h);
      cairo_stroke(cr);
      cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
      text(cr, xx, py + panel_h + 15, 11, number(t, decimals_for(t_step)), Align::kCentre);
    }
    cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
    cairo_rectangle(cr, left + 0.5, py + 0.5, right - left - 1, panel_h - 1);
    cairo_stroke(cr);
    if (p + 1 == panels.size()) text(cr, (left + right) / 2, py + panel_h + 32, 12, "time (s)", Align::kCentre);

    cairo_save(cr);
    cairo_rectangle(cr, left, py, right - left, panel_h);
    cairo_clip(cr);
    cairo_set_line_width(cr, 1.6);
    cairo_set_line_join(cr, CAIRO_LINE_JOIN_ROUND);
    for (size_t m = 0; m < cmp.methods.size(); ++m) {
      const std::vector<double>& series = cmp.methods[m].errors.*panels[p].series;
      set_colour(cr, method_colour(static_cast<int>(m)));
      bool pen = false;
      for (int f = 0; f < n; ++f) {
        const double v = series[static_cast<size_t>(f)];
        if (!std::isfinite(v)) {
          pen = false;
          continue;
        }
        const double xx = px(f / cmp.fps), yy = py_of(v);
        if (pen) {
          cairo_line_to(cr, xx, yy);
        } else {
          cairo_move_to(cr, xx, yy);
          if (n == 1) cairo_line_to(cr, xx + 1, yy);
        }
        pen = true;
      }
      cairo_stroke(cr);
    }
    cairo_restore(cr);
  }
  return canvas.png();
}

std::vector<std::uint8_t> animation_frame_png(const Comparison& cmp, int frame) {
  BODYD_REQUIRE(frame >= 0 && frame < cmp.frame_count(),
                fmt::format("animation frame {} of a clip of {} frames", frame, cmp.frame_count()));
  const Joints jn(cmp.skeleton);
  const ImageSize size = kAnimationFrameSize;
  Canvas canvas(size.width, size.height);
  cairo_t* cr = canvas.cr();
  cairo_set_source_rgb(cr, 0.05, 0.05, 0.05);
  text(cr, 10, 20, 13, cmp.clip_name, Align::kLeft, true);
  cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
  text(cr, size.width - 10, 20, 11,
       fmt::format("frame {} / {}  ({} s)", frame, cmp.frame_count() - 1, number(frame / cmp.fps, 2)), Align::kRight);
  double x = 10;
  for (size_t m = 0; m < cmp.methods.size(); ++m) {
    const FrameErrors& e = cmp.methods[m].errors;
    const std::string s = fmt::format("{}: {} cm (lower {}, hands {})", cmp.methods[m].track.label,
                                      number(e.all_cm[static_cast<size_t>(frame)], 1),
                                      number(e.lower_cm[static_cast<size_t>(frame)], 1),
                                      number(e.hands_cm[static_cast<size_t>(frame)], 1));
    set_colour(cr, method_colour(static_cast<int>(m)));
    text(cr, x, 38, 11, s);
    cairo_text_extents_t ext;
    cairo_text_extents(cr, s.c_str(), &ext);
    x += ext.x_advance + 16;
  }
  const double header = 46, footer = 24;
  const double px_per_m = fit_scale(cmp, jn, size.height - header - footer - 22);
  draw_frame_views(cr, cmp, jn, frame, 0, header, size.width, size.height - header - footer, px_per_m, false);
  draw_legend(cr, cmp, 10, size.height - 8, 10);
  return canvas.png();
}

std::vector<std::uint8_t> animation_apng(const Comparison& cmp, const AnimationOptions& options) {
  // bodyd-render's --anim-every is checked where it is parsed.
  BODYD_REQUIRE(options.every >= 1, "animation: every must be at least 1");
  std::vector<std::vector<std::uint8_t>> pngs;
  for (int f = 0; f < cmp.frame_count(); f += options.every) pngs.push_back(animation_frame_png(cmp, f));
  const double delay_ms = std::round(1000.0 * options.every / cmp.fps);
  return assemble_apng(pngs, static_cast<std::uint16_t>(std::clamp(delay_ms, 1.0, 65535.0)), 1000);
}

}  // namespace bodyd::render
