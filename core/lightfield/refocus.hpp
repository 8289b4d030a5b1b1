// Computational refocusing (eqs 2-4) and perspective views (sec 3.4) of a rectified light field.
#pragma once

#include <vector>

#include "core/base/image.hpp"
#include "core/lightfield/light_field.hpp"
#include "core/optics/camera_model.hpp"

namespace plenopiv::lightfield {

// alpha = s'_i / s_i for an object at depth z (mm, +z away from the camera, 0 at the nominal
// focal plane): s'_i from the thin lens (eq 5) with s_o + z. InputError when z puts the object at
// or inside the main lens's focal length.
double alpha_for_depth(const optics::CameraModel& camera, double z_mm);
// Its inverse: the depth z (mm from the nominal focal plane, object space) a refocus parameter
// alpha brings into focus; NaN where alpha s_i is not beyond the main lens's focal length (no real
// object plane).
double depth_for_alpha(const optics::CameraModel& camera, double alpha);

// Eq 4 on the lens lattice: output pixel (i, j) is the virtual-sensor point x' = alpha * p(i, j)
// (p = lattice position of lens (i, j), so every image of a focal stack has the same scale and
// the chief ray u = 0 lands on lens (i, j)), and
//   I(i, j) = sum_uv L(u (1 - 1/alpha) + x'/alpha, v (1 - 1/alpha) + y'/alpha, u, v) / sum_uv 1
// over the valid samples: the 4D interpolation is bilinear in the raw pixels (rectify) times
// bilinear across lenses (LatticeInterpolator). Pixels with no valid sample are 0.
// Output: count_x x count_y pixels.
ImageF refocus(const LightField& field, double alpha);
// One image per alpha, in order.
std::vector<ImageF> focal_stack(const LightField& field, const std::vector<double>& alphas);
// Focus measure of a refocused image: sum I^2 / (sum I)^2, largest when the light is most
// concentrated (the particle in focus); 0 for a black image.
double focus_measure(const ImageF& image);
// Depth from focus: the object depth z (mm) in z_min, z_min + step, ... <= z_max whose refocused
// image has the largest focus_measure (the first such depth on ties).
double sharpest_depth_mm(const LightField& field, const optics::CameraModel& camera, double z_min_mm, double z_max_mm,
                         double step_mm);

// Sec 3.4: the view from aperture point (u, v) mm: per lens, L interpolated bilinearly between
// the four nearest aperture samples (invalid samples left out). InputError when (u, v) lies
// outside the sampled aperture. Output: count_x x count_y pixels.
ImageF perspective_view(const LightField& field, double u_mm, double v_mm);

}  // namespace plenopiv::lightfield
