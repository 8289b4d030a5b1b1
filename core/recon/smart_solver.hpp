// The simultaneous MART (SMART) of one image as an object with named steps: set up the voxels it
// solves, start them (ones or MLOS), then iterate (an optional momentum step, a projection
// compared with the image, a multiplicative update). Internal to core/recon.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/base/big_buffer.hpp"
#include "core/base/image.hpp"
#include "core/recon/active_set.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/sensor_blur.hpp"
#include "core/recon/voxel_selection.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::recon::detail {

// What a MartWorkspace holds. Every reconstruction sizes and writes each buffer before reading it.
struct MartBuffers {
  std::atomic<bool> busy{false};
  // Per sensor pixel: the thresholded image, ln I, and W E, which the log-ratios white · ln(I / W E)
  // overwrite band by band once its residual sums are taken (the back-projection reads them there).
  BigBuffer<float> data, log_data, projection;
  // Per active voxel: E, the back-projected update, and the momentum's three.
  BigBuffer<float> e, update, last, log_last, momentum;
  // Per live voxel: its position in the active set the start had (pruning keeps the order).
  BigBuffer<std::uint32_t> origin;
  // Per voxel of the box: 1 where a live voxel is above the prune cut (MartSettings::prune_depth_reach).
  BigBuffer<std::uint8_t> above_cut;
  // Per brick of local_prune_bricks(): the peak of the live voxels in it and, after the spread to
  // the bricks around, of its neighbourhood (MartSettings::prune_local_threshold).
  BigBuffer<float> local_peak, local_scratch;
  ActiveSet active;  // the live voxels, laid out again in place when pruned
  // The next active set's voxel list, built here and traded with the set's own (ActiveSet::assign),
  // so that the two lists' pages stay in from set to set and frame to frame.
  BigBuffer<std::uint32_t> next_voxels;
  ActiveSet::Workspace kernels;  // reused by every pass
  SelectScratch select;
};

// The bricks MartSettings::prune_local_threshold compares within: kLocalPruneBrick voxels each
// (fewer at the far faces), as a grid whose nodes are bricks.
Grid3 local_prune_bricks(const Grid3& voxels);

// One reconstruction: construct, then run() once. The settings must have been validated and the
// image checked (validate_image); `buffers` are the caller's for the duration.
class SmartSolver {
 public:
  SmartSolver(const WeightingOperator& op, const MartSettings& settings, MartBuffers& buffers);

  MartResult run(const ImageF& image, const IterationCallback& progress);

 private:
  // The thresholded image, the active voxels (dark pixels, region, field of view) and their
  // kernel layout; sizes the per-voxel and per-pixel buffers.
  void setup(const ImageF& image);
  // What a dark pixel recorded at most (the noise threshold, or half the faintest lit pixel),
  // then E⁰: ones, or MLOS scaled to the image's total light.
  void start();
  void start_mlos();
  // ln I, ln of the dark floor, and the momentum's buffers.
  void prepare_iterations();
  // Nesterov's momentum: E becomes the extrapolated y = x_k (x_k / x_(k-1))^beta.
  void extrapolate(float beta);
  // Projection W E (B W E with the sensor blur), the residual's sums and, if `with_ratio`, the
  // whitened log-ratios the update back-projects.
  void project_and_compare(bool with_ratio);
  double residual() const;  // ||I - W E|| / ||I|| of the last projection
  // E <- E exp(mu Wᵀ ratio).
  void update();
  // Whether the step just taken goes along the momentum (else the momentum restarts).
  bool step_along_momentum() const;
  // MartSettings::prune: voxels at or below the threshold set to 0, and the active set rebuilt
  // without the zeros once enough of them have gathered, unless `last` (after the last iteration).
  void prune(bool last);
  // prune()'s first half: live voxels at or below their cut set to 0 (the slice's or volume's, or
  // the neighbourhood's where higher; those the depth reach keeps aside).
  void zero_below_cut();
  // zero_below_cut()'s neighbourhood peaks: b_.local_peak per brick of `bricks`
  // (local_prune_bricks), each the peak of the live voxels in its brick and the bricks around it.
  void local_peaks(const std::vector<std::size_t>& run, const Grid3& bricks);
  // The active voxels' values into the result's volume.
  void write_volume();

  // The residual's sums and the log-ratios of pixels [i0, i1) of the projection (band `band`).
  void residual_band(int band, std::size_t i0, std::size_t i1);
  void ratio_band(std::size_t i0, std::size_t i1, const float* scale);
  // f(m) for every active voxel m, or f(m0, m1) over its ranges, in parallel.
  template <typename F>
  void for_voxels(F&& f) const;
  template <typename F>
  void for_voxel_ranges(F&& f) const;

  const WeightingOperator& op_;
  const MartSettings& settings_;
  MartBuffers& b_;
  MartResult result_;
  ActiveSet& active_;        // b_.active
  std::size_t n_ = 0;        // live voxels (the active set's)
  std::size_t n_start_ = 0;  // active voxels at the start, before any pruning
  double start_work_ = 0;    // their pass work
  const float* white_ = nullptr;
  float dark_floor_ = 0, log_floor_ = 0;
  std::vector<std::array<double, 2>> band_sums_;  // the residual's sums per projection band
  SensorBlur blur_;
};

}  // namespace plenopiv::recon::detail
