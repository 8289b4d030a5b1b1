// MART's depth response: what a pair's own processing measures in depth for known uniform depth
// shifts of simulated particles, per depth layer of the vector grid, and its inverse applied to w.
#pragma once

#include <array>
#include <cstddef>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "core/base/grid.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::process {

class PairProcessor;

// The true shifts the response is measured at, in depth voxels of the grid (voxel_z): two each
// way, because the response is neither proportional (the light MART leaves where lines of sight
// cross follows a shift less than the particles do) nor odd (a shift towards the focal plane comes
// out shorter than one away from it).
inline constexpr double kDepthResponseShiftsVoxel[] = {-1.0, -0.5, 0.5, 1.0};

// Each layer's mean is taken over at least this many vectors per shift where a particle set gives
// fewer (a small box: its vectors' w scatters from set to set by more than the shortfall's change
// across the layers), over at most kDepthResponseMostSets sets of particles per shift.
inline constexpr std::size_t kDepthResponseVectorsPerLayer = 400;
inline constexpr std::size_t kDepthResponseMostSets = 4;

// The least fraction of the outermost true shifts (either way) a layer must measure: below it the
// inverse would multiply w's random error by more than 1 / kDepthResponseLeast, and a depth that
// barely follows motion (the end slices of a volume without a depth guard, say) is better reported
// than amplified. A third, not a half: the layers next to the focal plane of a resampled
// (calibrated, rotated) array follow a voxel's shift by less than half, and corrected there w's
// error is still the smaller (docs/accuracy.md). An inner shift measured as less (MART locking a
// small shift to its voxels) is taken as this fraction of it: the inverse's slope stays at most
// 1 / kDepthResponseLeast there, and w about that shift is under-corrected rather than refused.
inline constexpr double kDepthResponseLeast = 1.0 / 3;

// Per depth layer of a DepthResponse, how far the error of the simulated pairs goes beyond the sigma the
// correlation statistics predicted there (MART's ghosts, depth elongation and lateral locking, the
// same in both exposures): u's and v's sigma are multiplied by the layer's RMS error over its RMS
// sigma, and the random error of w about the layer's mean for its shift, on pairs whose particles
// also move sideways at random, less that RMS sigma in quadrature, is added to w's sigma in
// quadrature. A factor for u and v, because their extra error follows the correlation's sigma: a
// component of whole voxels, which MART reconstructs alike in both exposures, correlates well and
// has little of it, and an added error would dwarf its sigma. Never narrower than the correlation's
// sigma. An uncertainty calibrated by simulation of the instrument's own camera, box, seeding and
// settings (the "uncertainty surface" of Timmins et al., Exp. Fluids 53 (2012) 1133), valid for
// flows near uniform over a window, as the response itself is.
struct SigmaWidening {
  double scale_u = 1, scale_v = 1;  // u's and v's sigma multiplied by these: finite, >= 1
  double unseen_w_mm = 0;           // w's added in quadrature, mm: finite, >= 0
  bool operator==(const SigmaWidening&) const = default;
};

// Per depth layer (node z index) of the vector grid, the mean w measured over the layer's valid
// vectors for each true shift, through (0, 0): a monotone piecewise-linear curve, inverted to take
// MART's depth response out of a measured w. Beyond the outermost shifts the end segments go on.
// With it, each layer's SigmaWidening.
class DepthResponse {
 public:
  // `true_mm`: the shifts, ascending, 0 among them; `measured_mm[layer][k]`: what the processing
  // measured for true_mm[k] (0 at the 0 shift); `widening[layer]`: how that layer's sigma is
  // widened (empty: not at all).
  // InputError, naming the layer's depth, when a layer's measured values do not rise with the true
  // ones, or an outermost one is less than kDepthResponseLeast of its true shift; an inner one that
  // is less is raised to that fraction for the inverse (counted in summary()).
  DepthResponse(Grid3 field_grid, std::vector<double> true_mm, std::vector<std::vector<double>> measured_mm,
                std::vector<SigmaWidening> widening = {});

  // The true shift that layer `layer` measures as `measured_mm`, and the inverse's slope there
  // (d true / d measured: what carries w's standard uncertainty).
  double true_mm(int layer, double measured_mm) const;
  double slope(int layer, double measured_mm) const;
  // w (and its uncertainty, where estimated) of every node of `field` taken through its layer's
  // inverse; each sigma first widened as its layer's SigmaWidening says, and sigma_method says so.
  // std::logic_error when `field` is not on the grid the response was measured on.
  void apply(VectorField& field) const;

  const Grid3& field_grid() const { return field_grid_; }
  const std::vector<double>& shifts_mm() const { return true_mm_; }
  const std::vector<std::vector<double>>& measured_mm() const { return measured_mm_; }
  // The curve the inverse follows: measured_mm() with every inner value under kDepthResponseLeast
  // of its shift raised to it.
  const std::vector<std::vector<double>>& curve_mm() const { return curve_mm_; }
  const std::vector<SigmaWidening>& sigma_widening() const { return widening_; }
  // Measured over true shift at the outermost shifts, the smallest and largest over the layers,
  // as "depth response over z <first>..<last layer> mm: <least>..<most> of +<shift> mm, ... of
  // -<shift> mm", then the inner shifts raised to kDepthResponseLeast (how many, over which
  // layers), then the largest widening of u, v and w over the layers.
  std::string summary() const;

  // The response as bytes (this build's layout) and back; deserialize throws InputError naming
  // the problem for bytes that are cut, too many, or not a response its constructor accepts.
  void serialize(std::string& out) const;
  static DepthResponse deserialize(std::string_view bytes);

 private:
  int segment(int layer, double measured_mm) const;                  // k: measured_mm lies in [m(k), m(k + 1)]
  double segment_slope(int layer, int k) const;                      // d true / d measured on segment k
  double along_segment(int layer, int k, double measured_mm) const;  // the true shift, on segment k
  Grid3 field_grid_;
  std::vector<double> true_mm_;
  std::vector<std::vector<double>> measured_mm_;
  std::vector<std::vector<double>> curve_mm_;  // measured_mm_, inner values raised
  std::vector<SigmaWidening> widening_;        // one per layer, or none
};

// The response of `processor`'s settings on its camera and lenses: for each of
// kDepthResponseShiftsVoxel, particles seeded uniformly at `seeding_ppm` particles per microlens
// through the reconstructed box and 1 mm beyond each face, rendered (core/sim) before and after a
// uniform depth shift (with lateral shifts that sweep one voxel across the box, so that every layer
// sees the sub-voxel lateral shifts a flow's vectors carry: most of them on a large box, the middle
// ones on a small one), and processed as any pair; one set of particles per shift, or as many as
// kDepthResponseVectorsPerLayer asks (at most kDepthResponseMostSets). Each set is processed a
// second time with every particle of its second frame also moved sideways by a random fraction of a
// voxel: a window of a flow holds particles at many lateral fractions, and its w averages their
// errors, while a window the sweep alone moves carries one fraction's. The widening of u's and v's
// sigma comes from the first pairs, that of w's from the second, where the processing estimates sigma.
// Deterministic (fixed seeds). Costs eight pairs' processing at the paper's scale (minutes), up to
// thirty-two on a small box (seconds). InputError as DepthResponse's constructor gives it for a
// response it refuses; a layer that does not follow the first (outermost) shift is refused as soon
// as that shift's pairs are in, without the rest. `progress` (optional) gets the fraction done after each
// pair, within it after every MART iteration and correlation pass, and while each frame is
// traced (0 during the first pair), on the calling thread; a caller ends the measurement there by
// throwing.
DepthResponse measure_depth_response(const PairProcessor& processor, const optics::CameraModel& camera,
                                     const optics::MicrolensArray& lenses, double seeding_ppm,
                                     const std::function<void(double)>& progress = {});

}  // namespace plenopiv::process
