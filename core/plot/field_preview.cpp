// PNG previews of vector fields drawn with PLplot: the one owner of preview plots.
#include "core/plot/field_preview.hpp"

#include <plstream.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "core/base/errors.hpp"
#include "core/piv/derived.hpp"
#include "core/piv/peak_fit.hpp"
#include "core/plot/plplot_page.hpp"
#include "core/plot/scales.hpp"

namespace plenopiv::plot {
namespace {

// Colours of cmap0 used below (index 0 is the paper, white).
enum Colour : PLINT { ink = 1, replaced_ink = 2, no_vector_grey = 3, frame_grey = 4 };

void set_colours(plstream& pls) {
  pls.scol0(ink, 0, 0, 0);
  pls.scol0(replaced_ink, 0, 170, 0);
  pls.scol0(no_vector_grey, 190, 190, 190);
  pls.scol0(frame_grey, 90, 90, 90);
  // ColorBrewer RdBu (reversed): blue negative, near-white zero, red positive.
  const PLFLT at[] = {0.0, 0.2, 0.4, 0.5, 0.6, 0.8, 1.0};
  const PLFLT r[] = {5, 67, 209, 247, 253, 214, 103}, g[] = {48, 147, 229, 247, 219, 96, 0},
              b[] = {97, 195, 240, 247, 199, 77, 31};
  PLFLT rr[7], gg[7], bb[7];
  for (int i = 0; i < 7; ++i) {
    rr[i] = r[i] / 255;
    gg[i] = g[i] / 255;
    bb[i] = b[i] / 255;
  }
  pls.scmap1n(256);
  pls.scmap1l(true, 7, at, rr, gg, bb, nullptr);
}

// A 2-D array as PLplot takes it: [i][j] with i along x, rows of pointers into one buffer (moved,
// never copied: a move keeps the buffer the rows point into).
class Plane {
 public:
  Plane(int nx, int ny, double fill) : ny_(ny), data_(std::size_t(nx) * ny, fill), rows_(std::size_t(nx)) {
    for (int i = 0; i < nx; ++i) rows_[std::size_t(i)] = data_.data() + std::size_t(i) * ny;
  }
  Plane(Plane&&) = default;
  Plane& operator=(Plane&&) = default;
  Plane(const Plane&) = delete;
  Plane& operator=(const Plane&) = delete;
  double& at(int i, int j) { return data_[std::size_t(i) * ny_ + j]; }
  double at(int i, int j) const { return data_[std::size_t(i) * ny_ + j]; }
  const PLFLT* const* rows() const { return rows_.data(); }

 private:
  int ny_;
  std::vector<PLFLT> data_;
  std::vector<const PLFLT*> rows_;
};

// What one slice of the field shows: node coordinates, in-plane velocity split into measured and
// replaced vectors, and the two colour quantities (NaN where there is no vector).
struct Slice {
  int nx = 0, ny = 0, k = 0;
  double x0 = 0, y0 = 0, dx = 1, dy = 1, z_mm = 0;
  Plane u_measured{1, 1, 0}, v_measured{1, 1, 0}, u_replaced{1, 1, 0}, v_replaced{1, 1, 0};
  Plane omega_z{1, 1, 0}, w{1, 1, 0};
  double max_speed = 0, max_omega = 0, max_w = 0;
  std::size_t measured = 0, replaced = 0, none = 0;
};

constexpr std::uint8_t kReplacedBits = piv::flag_second_peak | piv::flag_third_peak | piv::flag_interpolated;

Slice middle_slice(const VectorField& f, std::span<const std::uint8_t> flags) {
  Slice s;
  s.nx = f.grid.shape[0];
  s.ny = f.grid.shape[1];
  s.k = f.grid.shape[2] / 2;
  s.x0 = f.grid.origin_mm[0];
  s.y0 = f.grid.origin_mm[1];
  s.dx = f.grid.spacing_mm[0];
  s.dy = f.grid.spacing_mm[1];
  s.z_mm = f.grid.coordinate_mm(2, s.k);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (Plane* p : {&s.u_measured, &s.v_measured, &s.u_replaced, &s.v_replaced}) *p = Plane(s.nx, s.ny, 0);
  s.omega_z = Plane(s.nx, s.ny, nan);
  s.w = Plane(s.nx, s.ny, nan);
  const auto omega = piv::vorticity(f);
  const double to_m_per_s = 1e-3 / f.dt_s;
  for (int j = 0; j < s.ny; ++j)
    for (int i = 0; i < s.nx; ++i) {
      const std::size_t n = f.grid.index(i, j, s.k);
      if (!f.valid[n]) {
        ++s.none;
        continue;
      }
      const double u = f.dx_mm[n] * to_m_per_s, v = f.dy_mm[n] * to_m_per_s, w = f.dz_mm[n] * to_m_per_s;
      const bool replaced = !flags.empty() && (flags[n] & kReplacedBits);
      ++(replaced ? s.replaced : s.measured);
      (replaced ? s.u_replaced : s.u_measured).at(i, j) = u;
      (replaced ? s.v_replaced : s.v_measured).at(i, j) = v;
      s.max_speed = std::max(s.max_speed, std::hypot(u, v));
      s.w.at(i, j) = w;
      s.max_w = std::max(s.max_w, std::abs(w));
      if (std::isfinite(omega[2][n])) {
        s.omega_z.at(i, j) = omega[2][n];
        s.max_omega = std::max(s.max_omega, double(std::abs(omega[2][n])));
      }
    }
  return s;
}

// Tick steps per axis for the label callback.
struct TickSteps {
  double x = 1, y = 1;
};

void label_ticks(PLINT axis, PLFLT value, char* label, PLINT length, PLPointer data) {
  const auto* steps = static_cast<const TickSteps*>(data);
  const std::string text = tick_label(value, axis == PL_X_AXIS ? steps->x : steps->y);
  std::snprintf(label, std::size_t(length), "%s", text.c_str());
}

// Maps PLplot's grid indices (i, j) to node coordinates (mm).
struct NodeMap {
  double x0, y0, dx, dy;
};
void node_coordinates(PLFLT i, PLFLT j, PLFLT* x, PLFLT* y, PLPointer data) {
  const auto* m = static_cast<const NodeMap*>(data);
  *x = m->x0 + i * m->dx;
  *y = m->y0 + j * m->dy;
}

// The extent of the cells around the nodes (mm): x from xlo to xhi, y from ylo to yhi.
struct Extent {
  double xlo, xhi, ylo, yhi;
};
Extent extent_of(const Slice& s) {
  return {s.x0 - s.dx / 2, s.x0 + (s.nx - 0.5) * s.dx, s.y0 - s.dy / 2, s.y0 + (s.ny - 0.5) * s.dy};
}

// World window with y down (y grows towards the bottom of the image), as the upright image.
void set_window(plstream& pls, const Extent& e) { pls.wind(e.xlo, e.xhi, e.yhi, e.ylo); }

void draw_arrows(plstream& pls, const Slice& s, double scale) {
  NodeMap map{s.x0, s.y0, s.dx, s.dy};
  pls.width(1.2);
  pls.col0(ink);
  pls.vect(s.u_measured.rows(), s.v_measured.rows(), s.nx, s.ny, scale, node_coordinates, &map);
  pls.col0(replaced_ink);
  pls.vect(s.u_replaced.rows(), s.v_replaced.rows(), s.nx, s.ny, scale, node_coordinates, &map);
  pls.width(1);
}

// One panel in the page region x from `left` to `right` (normalised page coordinates): the
// colour quantity on its symmetric scale, the arrows, axes and the colour bar. Returns the
// viewport it drew the field in.
Extent draw_panel(plstream& pls, const Slice& s, const Plane& colour, double max_abs, const std::string& bar_label,
                  const std::string& title, double left, double right, double arrow_mm_per_m_per_s) {
  const Extent e = extent_of(s);
  const double bottom = 0.22, top = 0.83;
  // Equal mm on both axes; the colour bar and its labels take the region's right fifth.
  pls.vpas(left + 0.07, right - 0.11, bottom, top, (e.yhi - e.ylo) / (e.xhi - e.xlo));
  PLFLT vx0, vx1, vy0, vy1;
  pls.gvpd(vx0, vx1, vy0, vy1);
  set_window(pls, e);

  // Grey under everything: the cells without a vector keep it.
  pls.col0(no_vector_grey);
  const PLFLT fx[] = {e.xlo, e.xhi, e.xhi, e.xlo}, fy[] = {e.ylo, e.ylo, e.yhi, e.yhi};
  pls.fill(4, fx, fy);
  const SymmetricScale scale = symmetric_scale(max_abs);
  // Values outside -limit .. limit are not drawn: NaN (no vector) becomes one of them.
  Plane shown(s.nx, s.ny, 0);
  const double skip = -2 * scale.limit;
  for (int i = 0; i < s.nx; ++i)
    for (int j = 0; j < s.ny; ++j) {
      const double c = colour.at(i, j);
      shown.at(i, j) = std::isfinite(c) ? std::clamp(c, -scale.limit, scale.limit) : skip;
    }
  pls.imagefr(shown.rows(), s.nx, s.ny, e.xlo, e.xhi, e.ylo, e.yhi, -scale.limit, scale.limit, -scale.limit,
              scale.limit, nullptr, nullptr);
  draw_arrows(pls, s, arrow_mm_per_m_per_s);

  TickSteps steps{nice_step(e.xhi - e.xlo, 6), nice_step(e.yhi - e.ylo, 6)};
  pls.slabelfunc(label_ticks, &steps);
  pls.col0(ink);
  pls.box("bcnsto", steps.x, 0, "bcnstvo", steps.y, 0);
  pls.mtex("b", 3.0, 0.5, 0.5, "x (mm)");
  pls.mtex("l", 3.6, 0.5, 0.5, "y (mm)");
  pls.mtex("t", 1.0, 0.5, 0.5, title.c_str());

  // Colour bar: a gradient image beside the panel, ticks at the scale's steps.
  pls.vpor(vx1 + 0.012, vx1 + 0.027, vy0, vy1);
  pls.wind(0, 1, -scale.limit, scale.limit);
  constexpr int levels = 256;
  Plane bar(2, levels, 0);
  for (int j = 0; j < levels; ++j) bar.at(0, j) = bar.at(1, j) = -scale.limit + 2 * scale.limit * (j + 0.5) / levels;
  pls.imagefr(bar.rows(), 2, levels, 0, 1, -scale.limit, scale.limit, -scale.limit, scale.limit, -scale.limit,
              scale.limit, nullptr, nullptr);
  TickSteps bar_steps{1, scale.step};
  pls.slabelfunc(label_ticks, &bar_steps);
  pls.box("bc", 0, 0, "bcmtvo", scale.step, 0);
  pls.mtex("r", 5.2, 0.5, 0.5, bar_label.c_str());
  pls.slabelfunc(nullptr, nullptr);
  return {vx0, vx1, vy0, vy1};
}

// The key under the panels, in a window of the same mm per page unit as the panels (so the
// reference arrow has the arrows' scale): the reference arrow with its length, a replaced vector's
// colour, the grey of a node without a vector.
void draw_key(plstream& pls, const Slice& s, const Extent& left_viewport, double arrow_mm_per_m_per_s,
              double reference_m_per_s) {
  const Extent e = extent_of(s);
  const double left = 0.04, right = 0.98;
  pls.vpor(left, right, 0.02, 0.08);
  const double mm_per_page = (e.xhi - e.xlo) / (left_viewport.xhi - left_viewport.xlo);
  const double width_mm = (right - left) * mm_per_page;
  pls.wind(0, width_mm, 0, 1);
  const double length_mm = reference_m_per_s * arrow_mm_per_m_per_s, gap_mm = 0.012 * mm_per_page;
  double at = 0;
  const auto arrow = [&](Colour colour) {
    pls.col0(colour);
    pls.width(1.2);
    Plane u(1, 1, reference_m_per_s), v(1, 1, 0);
    NodeMap node{at + 0.5 * length_mm, 0.5, 1, 1};
    pls.vect(u.rows(), v.rows(), 1, 1, arrow_mm_per_m_per_s, node_coordinates, &node);
    pls.width(1);
    at += length_mm + gap_mm;
  };
  pls.schr(0, 0.75);
  // PLplot's API does not measure text: a sans-serif character is taken as 0.68 of the character
  // height wide (plgchr: height in mm of paper; plgspa: the page's width in the same mm).
  PLFLT page_x0, page_x1, page_y0, page_y1, default_height, height;
  pls.gspa(page_x0, page_x1, page_y0, page_y1);
  pls.gchr(default_height, height);
  const auto text = [&](const std::string& t) {
    pls.col0(ink);
    pls.ptex(at, 0.5, 1, 0, 0, t.c_str());
    at += (0.68 * height * double(t.size()) / (page_x1 - page_x0) + 0.03) * mm_per_page;
  };
  if (reference_m_per_s > 0) {
    arrow(ink);
    text(quantity_label(reference_m_per_s, "m/s"));
    arrow(replaced_ink);
    text("replaced (2nd/3rd peak, neighbour mean)");
  }
  pls.col0(no_vector_grey);
  const PLFLT gx[] = {at, at + gap_mm, at + gap_mm, at}, gy[] = {0.2, 0.2, 0.8, 0.8};
  pls.fill(4, gx, gy);
  at += 2 * gap_mm;
  text("no vector");
}

void check_inputs(const std::filesystem::path& png, const VectorField& f, std::span<const std::uint8_t> flags,
                  const PreviewSize& size) {
  const std::string what = png.string() + ": preview";
  const std::size_t n = f.grid.count();
  if (n == 0) throw InputError(what + ": the field has no nodes");
  for (const auto* a : {&f.dx_mm, &f.dy_mm, &f.dz_mm})
    if (a->size() != n) throw InputError(what + ": displacement arrays do not match the grid");
  if (f.valid.size() != n) throw InputError(what + ": valid does not match the grid");
  if (!flags.empty() && flags.size() != n)
    throw InputError(what + ": flags has " + std::to_string(flags.size()) + " values for " + std::to_string(n) +
                     " nodes");
  if (!(f.dt_s > 0)) throw InputError(what + ": dt_s must be > 0 to give velocities");
  if (size.width_px < 200 || size.height_px < 120) throw InputError(what + ": image smaller than 200 x 120 pixels");
}

}  // namespace

void write_field_preview(const std::filesystem::path& png, const VectorField& field,
                         std::span<const std::uint8_t> flags, const PreviewSize& size) {
  check_inputs(png, field, flags, size);
  const Slice s = middle_slice(field, flags);
  const double arrow_scale_mm = arrow_scale(s.max_speed, std::min(s.dx, s.dy));
  const double reference = reference_length(s.max_speed);

  draw_png_page(png, size.width_px, size.height_px, [&](plstream& pls) {
    set_colours(pls);
    pls.schr(0, 0.85);
    const Extent left = draw_panel(pls, s, s.omega_z, s.max_omega, "#gw#dz#u (1/s)",
                                   "vorticity #gw#dz#u and in-plane velocity (u, v)", 0.0, 0.5, arrow_scale_mm);
    draw_panel(pls, s, s.w, s.max_w, "w (m/s)", "out-of-plane velocity w and (u, v)", 0.5, 1.0, arrow_scale_mm);
    draw_key(pls, s, left, arrow_scale_mm, reference);
    // The figure's title: where the slice is and what it holds.
    pls.vpor(0, 1, 0.9, 1);
    pls.wind(0, 1, 0, 1);
    char title[256];
    std::snprintf(title, sizeof title,
                  "slice z = %.4g mm (node %d of %d), dt = %.4g #gms: %zu measured, %zu replaced, %zu without a vector",
                  s.z_mm == 0 ? 0.0 : s.z_mm, s.k + 1, field.grid.shape[2], field.dt_s * 1e6, s.measured, s.replaced,
                  s.none);
    pls.col0(ink);
    pls.schr(0, 1.0);
    pls.ptex(0.5, 0.5, 1, 0, 0.5, title);
  });
}

}  // namespace plenopiv::plot
