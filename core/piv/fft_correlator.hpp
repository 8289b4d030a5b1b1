// FFT cross-correlation of 3-D interrogation windows (FFTW, float): a + i b in one transform.
#pragma once

#include <array>
#include <cstddef>
#include <memory>
#include <span>
#include <vector>

namespace plenopiv::piv {

// How FFTW chooses its algorithm. estimate: from heuristics, the same plan in every process, so
// results are bit-identical between runs. measure: FFTW times candidate algorithms when the plan
// is made (once per window shape and process); faster transforms, but the chosen plan, and so
// the last bits of the results, may differ between processes (never between thread counts).
enum class FftPlanning { estimate, measure };

// Robust phase correlation's spectral weighting (Eckstein & Vlachos, Meas. Sci. Technol. 20 (2009)
// 055401) for one window shape: the cross-spectrum C(k) becomes C(k) G(k) / |C(k)|^whitening, G a
// Gaussian low-pass whose inverse transform is a Gaussian of standard deviation peak_sigma_voxel
// per axis. Phases carry the displacement; whitening evens out the weight the spectrum's bands get,
// so broad intensity (MART's haze along lines of sight) no longer outweighs the particles' finer
// detail, and G gives the peak a width the three-point fits can resolve.
class SpectralWeights {
 public:
  // whitening in (0, 1]; peak_sigma_voxel > 0 per axis.
  SpectralWeights(std::array<int, 3> shape, double whitening, const std::array<double, 3>& peak_sigma_voxel);
  float whitening() const { return whitening_; }
  // G over the half spectrum kx = 0 .. nx / 2, [kz][ky][kx].
  std::span<const float> gauss() const { return gauss_; }

 private:
  float whitening_;
  std::vector<float> gauss_;
};

// Correlates windows of one shape (nx, ny, nz; any size per axis). The FFTW plans are made once,
// in the constructor, under a process-wide mutex (FFTW's planner is not thread-safe). Each thread
// that calls `workspace()` gets its own aligned buffers (tbb::enumerable_thread_specific) and runs
// the shared plans on them with FFTW's new-array execute functions, which are thread-safe.
class FftCorrelator {
 public:
  // Per-thread buffers: fill window_a() and window_b() ([z][y][x], x fastest), then correlate().
  class Workspace {
   public:
    std::span<float> window_a();
    std::span<float> window_b();
    // R(s) = sum_x a'(x) b'(x + s) of the mean-subtracted windows a', b'; [z][y][x] with shift 0
    // at index 0 and negative shifts wrapped (cyclic). Valid until the next call, and the caller's
    // to rescale; the windows' contents are consumed. With `weights` (made for this shape) the
    // cross-spectrum is weighted first (SpectralWeights).
    std::span<float> correlate(const SpectralWeights* weights = nullptr);

   private:
    friend class FftCorrelator;
    struct Buffers;
    Workspace(const FftCorrelator& owner, std::unique_ptr<Buffers> buffers);
    const FftCorrelator* owner_;
    std::shared_ptr<Buffers> buffers_;
  };

  explicit FftCorrelator(std::array<int, 3> shape, FftPlanning planning = FftPlanning::estimate);
  // One correlator per (shape, planning) for the whole process, made on first request: plans
  // and per-thread buffers are reused by every later correlation of that window shape.
  static const FftCorrelator& shared(std::array<int, 3> shape, FftPlanning planning);
  ~FftCorrelator();
  FftCorrelator(const FftCorrelator&) = delete;
  FftCorrelator& operator=(const FftCorrelator&) = delete;

  // The calling thread's workspace (made on first use).
  Workspace& workspace() const;
  const std::array<int, 3>& shape() const { return shape_; }
  std::size_t size() const { return std::size_t(shape_[0]) * shape_[1] * shape_[2]; }

 private:
  struct Plans;
  std::array<int, 3> shape_;
  std::unique_ptr<Plans> plans_;
};

}  // namespace plenopiv::piv
