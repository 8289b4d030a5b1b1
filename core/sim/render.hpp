// Ray-traced plenoptic images (paper sec 4, fig 10): particles, calibration and white targets.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/sim/particles.hpp"

namespace plenopiv::sim {

// A dust particle on the sensor's cover glass: its shadow, a disk of `radius_px` whose edge blurs
// over `edge_px`, passes 1 - opacity of the light in its core. Position in pixel coordinates
// (integer = pixel centre).
struct DustSpot {
  double column = 0;
  double row = 0;
  double radius_px = 5;
  double edge_px = 2;
  double opacity = 0.5;  // 0..1
};

// The sensor's response to the rays that landed on a pixel. Defaults: a perfect linear sensor
// (one count per ray, no noise, no offset, 16 bits, clean), as the geometry tests want.
struct SensorModel {
  double electrons_per_ray = 1.0;     // photo-electrons each landed ray frees (>= 0)
  bool shot_noise = false;            // Poisson photon shot noise on the electrons
  double read_noise_electrons = 0.0;  // Gaussian read noise, standard deviation (>= 0)
  double dark_offset_dn = 0.0;        // added after gain, counts (>= 0)
  // A second readout tap's offset on top of it: added to the right half's pixels (x >= width / 2),
  // counts (>= 0), as a two-tap CCD's halves read out with different offsets.
  double right_half_offset_dn = 0.0;
  double gain_dn_per_electron = 1.0;  // (> 0)
  int bit_depth = 16;                 // 1..16: values saturate at 2^bit_depth - 1
  // Shadows on the sensor: a ray landing in one is absorbed with the shadow's local opacity
  // (drawn from the ray's own random stream), so `RenderResult::rays` holds them too.
  std::vector<DustSpot> dust;
};

// A second circular stop behind the main lens (a lens barrel or a field stop at the exit pupil
// side): rays outside its diameter at `distance_mm` behind the main lens, on the optical axis,
// are blocked. Off-axis microlenses then see the aperture cut into a cat's eye and the white image
// falls off towards the edge of the field, as with real lenses. diameter_mm 0: no such stop.
struct VignettingStop {
  double distance_mm = 0;
  double diameter_mm = 0;
};

struct RenderOptions {
  std::size_t rays_per_particle = 10000;
  // Diffraction as Gaussian jitter of each ray's position at the microlens plane and at the
  // sensor (paper sec 4.1: the diffraction-limited spot, 5.2 um). 0 switches it off.
  double diffraction_sigma_mm = 0.0052;
  // Main-lens aperture diameter; 0 = the camera's f_m / (f/#)_m.
  double aperture_diameter_mm = 0.0;
  // Rays are aimed at points uniform over a disk `aperture_overfill` times the aperture's
  // diameter; those outside the aperture are blocked and counted. 1 (default) aims every ray
  // through the aperture, as the paper does (its theta_min..theta_max); > 1 exercises the stop.
  double aperture_overfill = 1.0;
  VignettingStop vignetting;
  SensorModel sensor;
  // Each particle's light scaled by a log-normal factor exp(s g - s^2 / 2) (g standard normal: a
  // mean of 1, median exp(-s^2 / 2)), as real seeding particles differ in size and so in scattered
  // light; s >= 0 is the spread of its natural log, 0 (default): every particle the same. The
  // factor is drawn from brightness_seed and the particle's index, not the frame's seed, so a
  // particle keeps its brightness in both frames of a pair.
  double brightness_spread = 0.0;
  std::uint64_t brightness_seed = 0;
  // Called with the fraction of sources traced (about every 1 %, and at 1), on the calling thread
  // only: for progress displays, and where a caller may wait (the other threads trace on) or end
  // the render (an exception it throws stops the tracing and reaches render's caller, which
  // returns nothing). Empty: not called.
  std::function<void(double)> progress;
};

// Where the emitted rays went: landed + outside_sensor + missed_array + outside_aperture +
// absorbed = emitted. outside_aperture: blocked by the aperture or the vignetting stop;
// missed_array: passed the stops but fell beside the microlens array (blocked by its mount);
// outside_sensor: refracted by a microlens but beyond the sensor's edge; absorbed: by dust.
struct RayCounts {
  std::uint64_t emitted = 0;
  std::uint64_t outside_aperture = 0;
  std::uint64_t missed_array = 0;
  std::uint64_t outside_sensor = 0;
  std::uint64_t landed = 0;
  std::uint64_t absorbed = 0;
};

struct RenderResult {
  ImageU16 image;  // after the sensor model
  ImageF rays;     // landed rays per pixel, exact integers (float holds them exactly below 2^24)
  RayCounts counts;
};

// Renders point particles (object space, mm) seen by `camera` through the microlens array
// `array` (the simulator's true array: any lattice, rotation, offset and per-lens centres).
// Each particle emits rays_per_particle rays at aperture points uniform over the (overfilled)
// main-lens disk; each ray goes through the ray-transfer matrices of fig 10 (free space to the
// main lens, thin lens, free space s_i to the microlens plane, the struck microlens as affine
// optics about its own centre, free space f_l to the sensor) and adds one to the pixel it hits.
// Random numbers come from a splitmix64 stream per particle, seeded from (seed, particle index),
// and pixels accumulate integer counts, so the image is bit-identical at any thread count.
// Throws InputError for bad options (negative or non-finite values, array/camera mismatch).
RenderResult render(const optics::CameraModel& camera, const optics::MicrolensArray& array,
                    std::span<const Point3> particles_mm, const RenderOptions& options, std::uint64_t seed);
// The checks render() makes of `options` alone (a negative or non-finite aperture, a brightness
// spread outside 0..3): InputError naming the option. For callers that take options long before
// they render (a simulated camera's URI at open).
void check_render_options(const RenderOptions& options);

// A uniformly lit, Lambertian white target at the nominal focal plane, covering the field of
// view of the array plus one pitch. rays_per_lens rays per lens area, from points uniform over
// the target, through points uniform over the aperture of f-number `f_number`.
struct TargetOptions {
  double f_number = 0.0;  // 0: the camera's f-number (white image); large: stopped down
  std::size_t rays_per_lens = 2000;
  double diffraction_sigma_mm = 0.0052;
  VignettingStop vignetting;
  SensorModel sensor;
  std::function<void(double)> progress;  // as RenderOptions::progress
};
// Calibration image (paper sec 3.2, fig 7): the aperture stopped down (default f/16) so each
// microlens shows one small spot at optics::lens_centre_to_spot_mm of its centre.
TargetOptions calibration_target();
// White image: the aperture as set on the camera, each microlens image a full disk.
TargetOptions white_target();
RenderResult render_target(const optics::CameraModel& camera, const optics::MicrolensArray& array,
                           const TargetOptions& options, std::uint64_t seed);

// The sensor model applied to landed-ray counts; noise from a stream per row seeded from
// (seed, row), so the result does not depend on the thread count.
ImageU16 apply_sensor(const ImageF& rays, const SensorModel& sensor, std::uint64_t seed);

// An imperfect array: `lattice` with each lens centre moved by Gaussian jitter (sigma_mm per
// axis), seeded.
optics::MicrolensArray jittered_array(const optics::Lattice& lattice, double sigma_mm, std::uint64_t seed);

// An array as mounted in a real camera: `layout` lenses of `pitch_mm` (row pitch sqrt(3)/2 of it
// for hex), turned by `rotation_rad` and shifted by (offset_x_mm, offset_y_mm) on the microlens
// plane, with enough lenses that the sensor sees the array reach past all four of its edges by at
// least `margin_lenses` lenses (the outer ones cut by the sensor edge or beyond it).
optics::Lattice overfilling_lattice(const optics::CameraModel& camera, optics::LensletLayout layout, double pitch_mm,
                                    double rotation_rad, double offset_x_mm, double offset_y_mm, int margin_lenses = 2);

}  // namespace plenopiv::sim
