// Resampling a raw plenoptic image onto an axis-aligned virtual microlens lattice (DESIGN.md's
// "rectified light field"), so that the separable weights of core/recon serve a calibrated array
// that is rotated, warped or hexagonal.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::lightfield {

// The virtual lattice a calibrated array is resampled onto: rectangular, not rotated, centred
// where the calibrated lattice is, every centre exactly on it. Rect: the calibrated lattice's lens
// count and (fitted, mean) pitches. Hex: the same number of lenses per row at the hex pitch, and
// rows one pitch apart (not the hex row spacing, pitch sqrt(3)/2: the microlens images, one pitch
// across, would overlap), as many as fit in the calibrated array's height.
optics::MicrolensArray axis_aligned_lattice(const optics::MicrolensArray& calibrated);

// A raw image as the sensor behind the axis-aligned lattice would have recorded it.
//
// For every virtual pixel: the virtual lens whose spot is nearest (every pixel has one), its
// offset from that spot, which fixes the aperture point it sees (eq 1); the virtual lens's centre
// in the calibrated lattice's coordinates (LatticeInterpolator, refined so that the interpolated
// position of the surrounding measured centres is the virtual centre: piecewise bilinear between
// the actual lenses, so a warped array is followed, not just its fitted lattice); then, for each of
// those up to 4 calibrated lenses, the raw pixel at the same offset from that lens's own spot (the
// same aperture point, to the nearest pixel), weighted by the lens weight: bilinear across lenses,
// nearest in raw pixels. Up to 4 raw pixels per virtual pixel with fixed weights: the resampling
// is one linear map R.
//
// Why the nearest raw pixel and not bilinear: a bilinear blend of the pixels around the sub-pixel
// position blurs the aperture coordinate by up to a pixel (1/17 of the aperture on the small
// camera) and fills in the pixels that recorded nothing, which is where MART's depth
// discrimination comes from (a voxel seen by a dark pixel is zero). Measured through
// `plenopiv process` on a 1 deg array (docs/benchmarks.md, "Rotated arrays"): the 0.25 mm depth
// shift came back as 0.03 mm with bilinear pixels and 0.10 mm with the nearest pixel (raw pixels
// of the unrotated camera: 0.15 mm), the lateral components equal or better. The rounding moves
// the aperture point by at most half a pixel.
//
// Nearest lens within a tolerance: a virtual lens whose nearest calibrated lens (the largest lens
// weight) lies within `whole_lens_px` of it along both axes takes that lens alone, at its spot's
// rounded shift (weight 1, or the lens weights' sum at the array's edge). A blend with a few
// percent of a neighbour lights pixels that recorded nothing (MART's depth discrimination) to move
// the sample by under a pixel, which the separable weights already ignore on an array within
// recon::kSeparableTolerancePx of its rows and columns (core/process passes that tolerance); beyond
// it the blend's position is worth its light. 0 blends every lens.
//
// White correction: the virtual sensor's white image is R applied to the calibrated white
// correction. A raw pixel records white x light field, so R(raw) = R(white) x the light field at
// the virtual lens wherever the light field varies slowly across neighbouring lenses: the
// weighting model (white_i times the ray weights) holds on the virtual sensor with R(white) as
// its white image, with no division by small white values at the rims. Where a virtual lens lies
// partly or wholly beyond the calibrated array (the corners of a rotated one), the lens weights
// sum to less than 1 in both the image and its white, so their ratio stays right.
//
// Why not rectify() followed by an interpolation in (u, v): rectify samples fixed aperture points
// bilinearly, and the virtual pixels see other ones (their spots sit at fractional pixel
// positions), so the raw pixels would be interpolated twice.
class LatticeResampler {
 public:
  // `white`: the calibrated white correction (sensor-sized, finite, non-negative). Throws
  // InputError naming what does not match the camera.
  // `whole_lens_px` >= 0 (see above; InputError otherwise).
  LatticeResampler(const optics::CameraModel& camera, const optics::MicrolensArray& calibrated, const ImageF& white,
                   double whole_lens_px = 0);

  // The virtual lattice (axis_aligned_lattice of the calibrated array) and the virtual sensor's
  // white image: what the weighting operator is built from.
  const optics::MicrolensArray& lenses() const { return virtual_; }
  const ImageF& white() const { return white_; }

  // `raw` must be the sensor's size (not checked for values: R keeps finite, non-negative images
  // finite and non-negative). `out` is resized to it and overwritten. Parallel over rows; every
  // pixel's sum has a fixed order, so the result does not depend on the thread count.
  void resample(const ImageF& raw, ImageF& out) const;
  ImageF resample(const ImageF& raw) const;

  // Coverage of the virtual lenses by the calibrated array: fully inside it, partly (at its edge),
  // and not at all (beyond it: their pixels stay 0).
  struct Coverage {
    int full = 0, partial = 0, none = 0;
    int nearest = 0;  // of full and partial: taken from one calibrated lens alone
  };
  const Coverage& coverage() const { return coverage_; }

 private:
  // One calibrated lens as seen from one virtual lens: the raw pixel offset (the spot-to-spot
  // shift, rounded) and the lens weight.
  struct Tap {
    std::int32_t dc = 0, dr = 0;
    float w = 0;
  };
  void apply(const ImageF& in, ImageF& out) const;

  optics::MicrolensArray virtual_;
  int width_ = 0, height_ = 0;
  // The virtual lens of pixel (col, row) is lens_column_[col] + count_x * lens_row_[row].
  std::vector<std::int32_t> lens_column_, lens_row_;
  std::vector<std::uint32_t> tap_start_;  // per virtual lens: taps [tap_start_[v], tap_start_[v + 1])
  std::vector<Tap> taps_;
  ImageF white_;
  Coverage coverage_;
};

}  // namespace plenopiv::lightfield
