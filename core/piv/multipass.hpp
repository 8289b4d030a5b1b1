// Multi-pass, multigrid 3D cross-correlation with window deformation (VODIM, paper sec 6.3).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "core/base/grid.hpp"
#include "core/piv/settings.hpp"

namespace plenopiv::piv {

// What one pass did, for progress output and the run's record.
struct PassReport {
  int pass = 0;  // 1-based
  int passes = 0;
  PassSettings settings;
  std::array<int, 3> vectors{0, 0, 0};  // nodes per axis
  std::size_t windows = 0;              // nodes in total
  std::size_t no_signal = 0;            // windows skipped: no particle signal (invalid)
  ValidationCounts validation;          // outliers and how they were replaced
  std::size_t flag_parabolic = 0;       // primary peaks fitted by the parabolic fallback
  std::size_t flag_centroid = 0;        // primary peaks on the window border (centroid)
  // Final pass (FinalPeakSearch::near_predictor): peaks found at the predictor without the FFT
  // that the median test kept (their peak ratio NaN), and peaks found there that it rejected, whose
  // windows were then correlated over all shifts (the two sum to the peaks found there).
  std::size_t near_peaks = 0;
  std::size_t near_rejected = 0;
  double deform_s = 0, correlate_s = 0, validate_s = 0;
  double uncertainty_s = 0;  // the final pass's per-vector uncertainty (part of validate_s)
};

struct CorrelationResult {
  VectorField field;                // displacement (mm) and its sigma, valid, peak ratio, dt_s, grid (mm)
  std::vector<std::uint8_t> flags;  // VectorFlag bits per node (peak_fit.hpp)
  std::vector<PassReport> passes;
};

// The correlation's volume-sized buffers (the floored, smoothed and deformed copies of both
// volumes: four volumes), kept by a caller that correlates pair after pair, so that no call
// allocates and page-faults them again. It carries nothing from one call to the next (every
// buffer is written before it is read): the same bits with a new workspace, a used one, or none.
// Buffers grow to the largest volume seen. One correlation at a time: a second one while the
// first runs is a bug in the caller (std::logic_error).
class CorrelationWorkspace {
 public:
  CorrelationWorkspace();
  ~CorrelationWorkspace();
  CorrelationWorkspace(CorrelationWorkspace&&) noexcept;
  CorrelationWorkspace& operator=(CorrelationWorkspace&&) noexcept;
  std::size_t bytes() const;  // held (the buffers' capacities)
  // Sizes and writes the buffers for volumes of `voxels` voxels (the reconstruction grid's count),
  // so that correlations of such volumes afterwards neither allocate nor page-fault them (as
  // recon::MartWorkspace::reserve). std::logic_error while a correlation uses the workspace.
  void reserve(std::size_t voxels);

  struct Buffers;

 private:
  std::unique_ptr<Buffers> buffers_;
  friend CorrelationResult correlate_volumes(const Volume&, const Volume&, const CorrelationSettings&,
                                             const std::function<void(const PassReport&)>&, int, CorrelationWorkspace*);
};

// Correlates volume `a` (first exposure) with `b` (second). Both must be on the same grid
// (InputError otherwise, as for non-finite voxels and windows larger than the volume). The
// vector grid's node (i, j, k) is the centre of its window, in mm. `on_pass` is called after
// each pass. Parallel (TBB) over windows and voxels; the result does not depend on the number
// of threads.
//
// `depth_context`: slices at each depth end that hold no window but that the correlation may
// read: a window's depth margin, the deformation, the prefilter (and the intensity floor's mean is
// taken over the whole volume, context included). The vectors are those of the volume without
// them (the same nodes), measured with what lies beyond its depth faces in view.
// core/process passes its depth guard here: a reconstructed particle is a streak in depth, and
// a box face cuts it as a window face does (PassSettings::depth_margin). 0 to less than half the
// volume's depth. `workspace`: the buffers, kept by the caller (the same bits without one).
CorrelationResult correlate_volumes(const Volume& a, const Volume& b, const CorrelationSettings& settings,
                                    const std::function<void(const PassReport&)>& on_pass = {}, int depth_context = 0,
                                    CorrelationWorkspace* workspace = nullptr);

}  // namespace plenopiv::piv
