// Test support: the raw plenoptic image of point particles, traced ray by ray through a thin main
// lens and thin microlenses (just enough optics to test refocusing and perspective against eq 2).
#pragma once

#include <array>
#include <vector>

#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::testing_support {

struct PointParticle {
  double x_mm = 0, y_mm = 0, z_mm = 0;  // object space, z = 0 at the nominal focal plane
  double intensity = 1000;              // total light reaching the sensor
};

// Rays from each particle through an n x n grid of aperture points (those inside the aperture
// disc), to the microlens plane (eq 2), through the lens whose centre is nearest, to the sensor,
// splatted bilinearly.
ImageF render_particles(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                        const std::vector<PointParticle>& particles, int n = 400);

// Where a particle's image forms behind the main lens: x' (mm, relative to the optical axis) and
// alpha = s'_i / s_i.
struct ImagePoint {
  double x_mm, y_mm, alpha;
};
ImagePoint image_point(const optics::CameraModel& camera, const PointParticle& p);

}  // namespace plenopiv::testing_support
