// FFT cross-correlation of 3-D interrogation windows: FFTW real-to-complex, single precision.
#include "core/piv/fft_correlator.hpp"

#include <fftw3.h>
#include <tbb/enumerable_thread_specific.h>

#include <map>
#include <mutex>
#include <utility>
#include <new>

namespace plenopiv::piv {
namespace {

// FFTW's planner (and plan destruction) must not run concurrently, in this library or any other.
std::mutex& fftw_planner_mutex() {
  static std::mutex m;
  return m;
}

template <typename T>
T* fftw_array(std::size_t count) {
  void* p = fftwf_malloc(sizeof(T) * count);
  if (!p) throw std::bad_alloc();
  return static_cast<T*>(p);
}

}  // namespace

// Aligned buffers from fftwf_malloc, so the plans' alignment assumptions hold for every thread.
struct FftCorrelator::Workspace::Buffers {
  std::size_t real_count, complex_count;
  float* a;
  float* b;
  fftwf_complex* fa;
  fftwf_complex* fb;
  float* corr;

  Buffers(std::size_t n_real, std::size_t n_complex)
      : real_count(n_real),
        complex_count(n_complex),
        a(fftw_array<float>(n_real)),
        b(fftw_array<float>(n_real)),
        fa(fftw_array<fftwf_complex>(n_complex)),
        fb(fftw_array<fftwf_complex>(n_complex)),
        corr(fftw_array<float>(n_real)) {}
  ~Buffers() {
    fftwf_free(a);
    fftwf_free(b);
    fftwf_free(fa);
    fftwf_free(fb);
    fftwf_free(corr);
  }
  Buffers(const Buffers&) = delete;
  Buffers& operator=(const Buffers&) = delete;
};

struct FftCorrelator::Plans {
  fftwf_plan forward = nullptr;
  fftwf_plan inverse = nullptr;
  tbb::enumerable_thread_specific<Workspace> workspaces;

  template <typename Init>
  explicit Plans(Init init) : workspaces(init) {}
};

FftCorrelator::Workspace::Workspace(const FftCorrelator& owner, std::unique_ptr<Buffers> buffers)
    : owner_(&owner), buffers_(std::move(buffers)) {}

std::span<float> FftCorrelator::Workspace::window_a() { return {buffers_->a, buffers_->real_count}; }
std::span<float> FftCorrelator::Workspace::window_b() { return {buffers_->b, buffers_->real_count}; }

std::span<const float> FftCorrelator::Workspace::correlate() {
  Buffers& w = *buffers_;
  const std::size_t n = w.real_count;
  // Mean subtraction removes the pedestal that would otherwise put a broad peak at shift 0.
  double sum_a = 0, sum_b = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sum_a += w.a[i];
    sum_b += w.b[i];
  }
  const float mean_a = float(sum_a / double(n)), mean_b = float(sum_b / double(n));
  for (std::size_t i = 0; i < n; ++i) {
    w.a[i] -= mean_a;
    w.b[i] -= mean_b;
  }
  fftwf_execute_dft_r2c(owner_->plans_->forward, w.a, w.fa);
  fftwf_execute_dft_r2c(owner_->plans_->forward, w.b, w.fb);
  // conj(A) * B, scaled by 1/n so the inverse transform gives the plain correlation sum.
  const float scale = 1.f / float(n);
  for (std::size_t k = 0; k < w.complex_count; ++k) {
    const float ar = w.fa[k][0], ai = w.fa[k][1], br = w.fb[k][0], bi = w.fb[k][1];
    w.fa[k][0] = (ar * br + ai * bi) * scale;
    w.fa[k][1] = (ar * bi - ai * br) * scale;
  }
  fftwf_execute_dft_c2r(owner_->plans_->inverse, w.fa, w.corr);
  return {w.corr, n};
}

FftCorrelator::FftCorrelator(std::array<int, 3> shape, FftPlanning planning) : shape_(shape) {
  const std::size_t n_real = size();
  const std::size_t n_complex = std::size_t(shape[2]) * shape[1] * (shape[0] / 2 + 1);
  plans_ = std::make_unique<Plans>([this, n_real, n_complex] {
    return Workspace(*this, std::make_unique<Workspace::Buffers>(n_real, n_complex));
  });
  Workspace::Buffers probe(n_real, n_complex);
  std::lock_guard lock(fftw_planner_mutex());
  // FFTW takes the slowest-varying dimension first: [z][y][x].
  const unsigned flags = planning == FftPlanning::measure ? FFTW_MEASURE : FFTW_ESTIMATE;
  plans_->forward = fftwf_plan_dft_r2c_3d(shape[2], shape[1], shape[0], probe.a, probe.fa, flags);
  plans_->inverse = fftwf_plan_dft_c2r_3d(shape[2], shape[1], shape[0], probe.fa, probe.corr, flags);
  if (!plans_->forward || !plans_->inverse) throw std::bad_alloc();
}

FftCorrelator::~FftCorrelator() {
  std::lock_guard lock(fftw_planner_mutex());
  fftwf_destroy_plan(plans_->forward);
  fftwf_destroy_plan(plans_->inverse);
}

const FftCorrelator& FftCorrelator::shared(std::array<int, 3> shape, FftPlanning planning) {
  // The planner mutex must outlive the cache, whose destructors take it: construct it first.
  fftw_planner_mutex();
  static std::mutex m;
  static std::map<std::pair<std::array<int, 3>, FftPlanning>, std::unique_ptr<FftCorrelator>> cache;
  std::lock_guard lock(m);
  auto& slot = cache[{shape, planning}];
  if (!slot) slot = std::make_unique<FftCorrelator>(shape, planning);
  return *slot;
}

FftCorrelator::Workspace& FftCorrelator::workspace() const { return plans_->workspaces.local(); }

}  // namespace plenopiv::piv
