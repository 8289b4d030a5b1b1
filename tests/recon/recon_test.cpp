// core/recon: the plenoptic weights against their explicit reference, MART's forms against each
// other and against known blob volumes, stability at the edges of the input space, Q*, the fit.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>
#include <limits>
#include <numeric>
#include <random>
#include <span>
#include <tuple>

#include "core/base/errors.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/recon/active_set.hpp"
#include "core/recon/explicit_matrix.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/quality.hpp"
#include "core/recon/weights.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::recon {
namespace {

optics::CameraModel small_camera() {
  return optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
}

// A box centred on the optical axis: n x n lateral voxels of 0.125 mm, nz slices `dz` apart from z0.
Grid3 centred_grid(int n, int nz, double dz, double z0) {
  Grid3 g;
  g.shape = {n, n, nz};
  g.spacing_mm = {0.125, 0.125, dz};
  g.origin_mm = {-0.5 * (n - 1) * 0.125, -0.5 * (n - 1) * 0.125, z0};
  return g;
}

WeightingOperator make_operator(const optics::CameraModel& cam, const Grid3& g) {
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  return WeightingOperator(cam, lenses, g, calib::geometric_white_image(cam, lenses));
}

// Particles as Gaussian blobs (sigma in voxels) at voxel positions: the truth for Q*.
Volume blob_volume(const Grid3& g, const std::vector<std::array<double, 3>>& centres, double sigma_xy, double sigma_z) {
  Volume v(g, 0.f);
  for (int z = 0; z < g.shape[2]; ++z) {
    for (int y = 0; y < g.shape[1]; ++y) {
      for (int x = 0; x < g.shape[0]; ++x) {
        double s = 0;
        for (const auto& c : centres) {
          const double dx = x - c[0], dy = y - c[1], dz = z - c[2];
          s += std::exp(-0.5 * ((dx * dx + dy * dy) / (sigma_xy * sigma_xy) + dz * dz / (sigma_z * sigma_z)));
        }
        v.at(x, y, z) = float(s);
      }
    }
  }
  return v;
}

ImageF project_image(const WeightingOperator& op, const Volume& v, float scale) {
  ImageF img(op.image_width(), op.image_height(), 0.f);
  op.project(v.data, img.pixels);
  for (float& p : img.pixels) p *= scale;
  return img;
}

bool all_finite_bounded(const Volume& v, float bound) {
  for (float x : v.data) {
    if (!std::isfinite(x) || x < 0 || x > bound) return false;
    if (x != 0 && std::fpclassify(x) == FP_SUBNORMAL) return false;
  }
  return true;
}

class Weights : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    camera_ = new optics::CameraModel(small_camera());
    // Slices on both sides of focus and at it: 10 x 10 x 9 voxels, z from -4 to +4 mm.
    op_ = new WeightingOperator(make_operator(*camera_, centred_grid(10, 9, 1.0, -4.0)));
    matrix_ = new SparseMatrix(build_explicit_matrix(*op_));
  }
  static void TearDownTestSuite() {
    delete matrix_;
    delete op_;
    delete camera_;
  }
  static optics::CameraModel* camera_;
  static WeightingOperator* op_;
  static SparseMatrix* matrix_;
};
optics::CameraModel* Weights::camera_ = nullptr;
WeightingOperator* Weights::op_ = nullptr;
SparseMatrix* Weights::matrix_ = nullptr;

double max_abs(std::span<const float> a) {
  double m = 0;
  for (float v : a) m = std::max(m, double(std::abs(v)));
  return m;
}
double max_abs_diff(std::span<const float> a, std::span<const float> b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, double(std::abs(a[i] - b[i])));
  return m;
}

TEST(MartNames, EveryValueHasOneNameAndAnUnknownNameIsRefusedByName) {
  for (const MartStart start : {MartStart::ones, MartStart::mlos})
    EXPECT_EQ(mart_start_named(name_of(start), "start"), start);
  for (const PruneScope scope : {PruneScope::volume, PruneScope::slice})
    EXPECT_EQ(prune_scope_named(name_of(scope), "prune_scope"), scope);
  EXPECT_EQ(name_of(MartStart::mlos), "mlos");
  EXPECT_EQ(name_of(PruneScope::slice), "slice");
  try {
    (void)prune_scope_named("lens", "--prune-scope");
    FAIL() << "an unknown scope was taken";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "--prune-scope: expected one of volume, slice, got 'lens'");
  }
  EXPECT_THROW((void)mart_start_named("MLOS", "start"), InputError);  // names are exact
}

TEST_F(Weights, GeometricWhiteImageIsOneInsideMicrolensImagesAndZeroBetween) {
  const ImageF& w = op_->white();
  // camera-small: 50 x 50 lenses of 16.89 px on 850 px, f-number matched, centred.
  const double pitch_px = camera_->pixels_per_microlens();
  const double c0 = 425 - 0.5 - 24.5 * pitch_px;  // column of lens 0's spot (M = -1: s_i = 100)
  EXPECT_FLOAT_EQ(w.at(int(std::lround(c0 + 10 * pitch_px)), int(std::lround(c0 + 10 * pitch_px))), 1.f);
  EXPECT_FLOAT_EQ(w.at(int(std::lround(c0 + 10.5 * pitch_px)), int(std::lround(c0 + 10.5 * pitch_px))), 0.f);
  // Light per lens: the disk area, pi r^2 (r = 8.45 px) = 224.3 px.
  double total = 0;
  for (float v : w.pixels) total += v;
  EXPECT_NEAR(total / 2500.0, M_PI * std::pow(0.5 * camera_->microlens_image_diameter_px(), 2), 0.5);
}

TEST_F(Weights, EveryVoxelColumnIsNormalised) {
  // Eq 13: the weights of each voxel sum to one (all its light reaches the sensor).
  std::vector<double> column_sum(matrix_->cols, 0.0);
  for (std::size_t k = 0; k < matrix_->nonzeros(); ++k) column_sum[matrix_->col_index[k]] += matrix_->values[k];
  for (double s : column_sum) EXPECT_NEAR(s, 1.0, 1e-5);
}

TEST_F(Weights, MatrixFreeProjectionEqualsExplicitMatrix) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<float> x(op_->grid().count());
  for (float& v : x) v = u(rng);
  std::vector<float> a(op_->pixel_count()), b(op_->pixel_count());
  op_->project(x, a);
  matrix_->multiply(x, b);
  std::cout << "measured: projection relative difference " << max_abs_diff(a, b) / max_abs(b) << "\n";
  EXPECT_LE(max_abs_diff(a, b) / max_abs(b), 1e-4);
  // One voxel at a time: every column, the same pixels and weights.
  for (std::size_t j : {std::size_t(0), std::size_t(455), op_->grid().count() - 1}) {
    std::vector<float> unit(op_->grid().count(), 0.f);
    unit[j] = 1.f;
    op_->project(unit, a);
    matrix_->multiply(unit, b);
    EXPECT_LE(max_abs_diff(a, b) / max_abs(b), 1e-4) << "voxel " << j;
  }
}

TEST_F(Weights, MatrixFreeBackProjectionEqualsExplicitTranspose) {
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u(0.f, 100.f);
  std::vector<float> y(op_->pixel_count());
  for (float& v : y) v = u(rng);
  std::vector<float> a(op_->grid().count()), b(op_->grid().count());
  op_->back_project(y, a);
  matrix_->multiply_transpose(y, b);
  std::cout << "measured: back-projection relative difference " << max_abs_diff(a, b) / max_abs(b) << "\n";
  EXPECT_LE(max_abs_diff(a, b) / max_abs(b), 1e-4);
}

TEST_F(Weights, ProjectionAndBackProjectionAreAdjoint) {
  std::mt19937 rng(9);
  std::normal_distribution<float> n(0.f, 1.f);
  std::vector<float> x(op_->grid().count()), y(op_->pixel_count());
  for (float& v : x) v = n(rng);
  for (float& v : y) v = n(rng);
  std::vector<float> wx(op_->pixel_count()), wty(op_->grid().count());
  op_->project(x, wx);
  op_->back_project(y, wty);
  double lhs = 0, rhs = 0, scale = 0;
  for (std::size_t i = 0; i < y.size(); ++i) {
    lhs += double(wx[i]) * y[i];
    scale += std::abs(double(wx[i]) * y[i]);
  }
  for (std::size_t j = 0; j < x.size(); ++j) rhs += double(x[j]) * wty[j];
  std::cout << "measured: adjointness " << std::abs(lhs - rhs) / scale << "\n";
  EXPECT_LE(std::abs(lhs - rhs) / scale, 1e-5);
}

// The kernels on a subset of the voxels of a grid wider than the sensor (its edge voxels reach the
// last pixel columns, where the 4-pixel quads shift inwards) and with several voxel x per strip,
// against the explicit matrix's columns for those voxels (the same 1e-4 relative bound as the
// dense operators).
// The weights cache's bytes (WeightingOperator::serialize / deserialize): read back to the same
// bytes, and cut short anywhere, with a byte too many, or with a slice's array claiming more
// elements than there are bytes, refused with InputError instead of read past their end (the
// slices are found by a pass over their sizes, then copied in parallel).
TEST(WeightsBytes, ReadBackTheSameAndRefuseDamagedBytes) {
  const auto cam = small_camera();
  const WeightingOperator op = make_operator(cam, centred_grid(8, 6, 1.0, -4.0));
  std::string bytes;
  op.serialize(bytes);
  const WeightingOperator back = WeightingOperator::deserialize(bytes);
  std::string again;
  back.serialize(again);
  EXPECT_TRUE(again == bytes);
  EXPECT_EQ(back.bytes(), op.bytes());
  for (int k = 0; k < 64; ++k) {
    const std::size_t cut = bytes.size() * std::size_t(k) / 64;
    EXPECT_THROW((void)WeightingOperator::deserialize(std::string_view(bytes).substr(0, cut)), InputError)
        << "cut at " << cut << " of " << bytes.size();
  }
  try {
    (void)WeightingOperator::deserialize(bytes + "x");
    ADD_FAILURE() << "a byte too many was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bytes left after the operator"), std::string::npos) << e.what();
  }
  // The last slice's last array (its y quad weights) says it holds far more floats than follow:
  // its count sits right before its floats and the normalisers' count and floats.
  const std::size_t tail = sizeof(std::uint64_t) + op.normalisers().size() * sizeof(float);
  const std::size_t last_weights = op.slice(op.grid().shape[2] - 1).y_quad_weights.size() * sizeof(float);
  std::string damaged = bytes;
  const std::uint64_t huge = std::uint64_t(1) << 40;
  std::memcpy(damaged.data() + bytes.size() - tail - last_weights - sizeof huge, &huge, sizeof huge);
  try {
    (void)WeightingOperator::deserialize(damaged);
    ADD_FAILURE() << "an array longer than the bytes was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("an array runs past the end"), std::string::npos) << e.what();
  }
}

TEST(WeightsActiveSet, SubsetOnAWideGridEqualsExplicitColumns) {
  const auto cam = small_camera();
  Grid3 g;
  g.shape = {24, 6, 5};  // 3 voxel x per strip
  g.spacing_mm = {0.3, 0.3, 2.0};
  g.origin_mm = {-3.45, -0.75, -4.0};  // x to +-3.45 mm; the sensor's half width is 3.15 mm
  const WeightingOperator op = make_operator(cam, g);
  int last_column = 0;
  for (int z = 0; z < g.shape[2]; ++z) {
    for (int x = 0; x < g.shape[0]; ++x) last_column = std::max(last_column, op.x_weights(z, x).last);
  }
  std::cout << "measured: last pixel column reached " << last_column << "\n";
  ASSERT_GT(last_column, op.image_width() - 4);
  // The kernels cut the sensor into bands of 256 rows (850 rows: 4 bands, the last partial) and
  // keep the y weights as 4-row quads: some quads must cross a band edge for this test to cover
  // the lanes that belong to the neighbouring band.
  int straddling = 0;
  for (int z = 0; z < g.shape[2]; ++z) {
    for (int first : op.slice(z).y_quad_first) straddling += first / 256 != (first + 3) / 256;
  }
  std::cout << "measured: y quads across a band edge " << straddling << "\n";
  ASSERT_GT(straddling, 0);
  const SparseMatrix w = build_explicit_matrix(op);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<std::uint32_t> subset;
  for (std::uint32_t v = 0; v < g.count(); ++v) {
    if (u(rng) < 0.5f) subset.push_back(v);
  }
  const ActiveSet set(op, subset);
  std::vector<float> values(subset.size()), full(g.count(), 0.f);
  for (std::size_t m = 0; m < subset.size(); ++m) full[subset[m]] = values[m] = u(rng);
  std::vector<float> a(op.pixel_count()), b(op.pixel_count());
  set.project(op, values, a);
  w.multiply(full, b);
  std::cout << "measured: subset projection relative difference " << max_abs_diff(a, b) / max_abs(b) << "\n";
  EXPECT_LE(max_abs_diff(a, b) / max_abs(b), 1e-4);
  std::vector<float> y(op.pixel_count()), back(subset.size()), reference(g.count()), expected(subset.size());
  for (float& v : y) v = 100.f * u(rng);
  set.back_project(op, y, back);
  w.multiply_transpose(y, reference);
  for (std::size_t m = 0; m < subset.size(); ++m) expected[m] = reference[subset[m]];
  std::cout << "measured: subset back-projection relative difference "
            << max_abs_diff(back, expected) / max_abs(expected) << "\n";
  EXPECT_LE(max_abs_diff(back, expected) / max_abs(expected), 1e-4);
}

TEST_F(Weights, RaySamplingFollowsSection52) {
  // At focus the nominal angular sampling (17 pixels across a microlens image); never a ray
  // spacing on the microlens plane of a pitch or more.
  for (int z = 0; z < op_->grid().shape[2]; ++z) {
    const SliceTables& t = op_->slice(z);
    EXPECT_GE(t.samples, 17);
    const double spacing = camera_->aperture_diameter_mm() / t.samples * std::abs(1 - 1 / t.alpha);
    EXPECT_LT(spacing, camera_->microlens().pitch_mm);
  }
  EXPECT_DOUBLE_EQ(op_->slice(4).alpha, 1.0);  // z = 0
  EXPECT_LT(op_->slice(8).alpha, 1.0);         // +z (away) images nearer the lens
  EXPECT_GT(op_->slice(0).alpha, 1.0);
}

TEST(WeightsInput, RejectsUnsupportedArraysAndDepthsInsideTheFocalLength) {
  const auto cam = small_camera();
  auto lattice = optics::Lattice::nominal(cam);
  lattice.rotation_rad = 0.01;  // 0.3 mm = 40 px at the array's corners
  const auto rotated = optics::MicrolensArray::from_lattice(lattice);
  EXPECT_THROW(WeightingOperator(cam, rotated, centred_grid(4, 2, 1, 0), ImageF(850, 850, 1.f)), InputError);
  const auto nominal = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  EXPECT_THROW(WeightingOperator(cam, nominal, centred_grid(4, 2, 1, 0), ImageF(10, 10, 1.f)), InputError);
  // s_o = 100 mm, f = 50 mm: z = -60 mm is inside the focal length.
  EXPECT_THROW(WeightingOperator(cam, nominal, centred_grid(4, 2, 1, -60), ImageF(850, 850, 1.f)), InputError);
}

TEST(WeightsInput, AngularSamplingScalesTheSamplesOfEverySlice) {
  const auto cam = small_camera();
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  const Grid3 g = centred_grid(4, 2, 9, 0);  // slices from -4 to +4 mm: the sec 5.2 count varies
  const WeightingOperator base(cam, lenses, g, calib::geometric_white_image(cam, lenses));
  const WeightingOperator fine(cam, lenses, g, calib::geometric_white_image(cam, lenses), 2.0);
  const WeightingOperator coarse(cam, lenses, g, calib::geometric_white_image(cam, lenses), 0.5);
  for (int z = 0; z < g.shape[2]; ++z) {
    const int n = base.slice(z).samples;
    EXPECT_GE(n, base.geometry().nominal_samples) << "slice " << z;
    EXPECT_EQ(fine.slice(z).samples, 2 * n) << "slice " << z;
    EXPECT_EQ(coarse.slice(z).samples, (n + 1) / 2) << "slice " << z;
  }
  for (double bad : {0.0, -1.0, 9.0}) {
    try {
      WeightingOperator(cam, lenses, g, calib::geometric_white_image(cam, lenses), bad);
      ADD_FAILURE() << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("angular_sampling"), std::string::npos) << e.what();
    }
  }
}

// ---------------------------------------------------------------------------------------------

class Mart : public Weights {
 protected:
  // Three particles at depths -2, 0.5 and 3 mm in the 10 x 10 x 9 box (voxels 1 mm deep).
  static Volume truth() { return blob_volume(op_->grid(), {{3, 4, 2}, {6, 6, 4.5}, {4, 7, 7}}, 0.7, 0.7); }
};

TEST_F(Mart, QualityRisesWithIterations) {
  const Volume exact = truth();
  const ImageF image = project_image(*op_, exact, 1000.f);
  double previous = -1;
  for (int iterations : {1, 5, 20}) {
    MartSettings s;
    s.iterations = iterations;
    const MartResult r = reconstruct(*op_, image, s);
    const double q = quality_factor(r.volume, exact);
    ASSERT_TRUE(r.final_residual);
    std::cout << "measured: Q* after " << iterations << " iterations " << q << ", residual " << *r.final_residual
              << "\n";
    // Q* grows with the iterations (an image from the operator itself: an optimistic case).
    EXPECT_GT(q, previous) << iterations << " iterations (measured 0.897, 0.963, 0.990 after 1, 5, 20)";
    previous = q;
    ASSERT_FALSE(r.iterations.empty());
    EXPECT_LE(*r.final_residual, r.iterations.front().residual);
  }
  EXPECT_GT(previous, 0.95);
}

// Nesterov's momentum: the same update per iteration, taken from an extrapolated volume.
TEST_F(Mart, AccelerationConvergesFasterPerIteration) {
  const Volume exact = truth();
  const ImageF image = project_image(*op_, exact, 1000.f);
  auto run = [&](int iterations, bool accelerate) {
    MartSettings s;
    s.iterations = iterations;
    s.mu = 1;
    s.accelerate = accelerate;
    const MartResult r = reconstruct(*op_, image, s);
    const double q = quality_factor(r.volume, exact);
    EXPECT_TRUE(r.final_residual);
    const double residual = r.final_residual.value_or(1.0);
    std::cout << "measured: " << iterations << (accelerate ? " accelerated" : " plain") << " iterations: Q* " << q
              << ", residual " << residual << "\n";
    EXPECT_TRUE(all_finite_bounded(r.volume, 1e30f));
    return std::pair{q, residual};
  };
  const auto [q4, res4] = run(4, false);
  const auto [q10, res10] = run(10, false);
  const auto [q4a, res4a] = run(4, true);
  const auto [q10a, res10a] = run(10, true);
  // Acceleration lowers the residual and raises Q* at the same iteration count.
  EXPECT_LT(res4a, 0.85 * res4) << "measured 0.0454 against 0.0614";
  EXPECT_LT(res10a, 0.75 * res10) << "measured 0.0184 against 0.0289";
  EXPECT_GT(q4a, q4);
  EXPECT_GT(q10a, q10);
}

TEST_F(Mart, RowActionAndSimultaneousFormsAgree) {
  const Volume exact = truth();
  const ImageF image = project_image(*op_, exact, 1000.f);
  MartSettings s;
  s.iterations = 10;
  s.start = MartStart::ones;
  s.dark_weight_cutoff = 0;
  const Volume simultaneous = reconstruct(*op_, image, s).volume;
  s.method = MartMethod::row_action;
  const Volume row_action = reconstruct_row_action(*op_, *matrix_, image, s);
  const double qs = quality_factor(simultaneous, exact), qr = quality_factor(row_action, exact);
  std::cout << "measured: Q* simultaneous " << qs << ", row-action " << qr << "\n";
  EXPECT_NEAR(qs, qr, 0.05) << "simultaneous " << qs << ", row-action " << qr << " (measured 0.973, 0.972)";
  EXPECT_GT(qs, 0.9);
}

TEST_F(Mart, VoxelsSeenByDarkPixelsAreSkippedAndStayZero) {
  const Volume exact = truth();
  const ImageF image = project_image(*op_, exact, 1000.f);
  MartSettings s;
  s.noise_threshold = 0.01f;
  s.dark_weight_cutoff = 0;  // eq 9 literally, as the row-action reference
  const MartResult r = reconstruct(*op_, image, s);
  const SkipReport& k = r.skipped;
  EXPECT_EQ(k.voxels, op_->grid().count());
  EXPECT_EQ(k.voxels_active + k.voxels_dark + k.voxels_unseen + k.voxels_outside_region, k.voxels);
  std::cout << "measured: skipped " << k.fraction_skipped() << " (dark " << k.voxels_dark << ", unseen "
            << k.voxels_unseen << ", active " << k.voxels_active << ")\n";
  EXPECT_GT(k.fraction_skipped(), 0.9) << "a sparse scene: measured 0.984";
  // The row-action reference zeroes the same voxels.
  s.method = MartMethod::row_action;
  s.iterations = 1;
  const Volume ref = reconstruct_row_action(*op_, *matrix_, image, s);
  std::size_t nonzero_ref = 0;
  for (std::size_t j = 0; j < ref.data.size(); ++j) {
    if (ref.data[j] > 0) ++nonzero_ref;
    if (r.volume.data[j] > 0) {
      EXPECT_GT(ref.data[j], 0.f) << "voxel " << j;
    }
  }
  EXPECT_EQ(nonzero_ref, k.voxels_active);
}

// What MART takes a dark pixel to have recorded: the noise threshold, or half the faintest lit
// pixel; a caller's floor (a resampled frame's raw one) replaces it. The image's own floor given
// changes no bit; a lower one changes the volume.
TEST_F(Mart, DarkFloorIsTheImagesOwnUnlessTheCallerGivesOne) {
  ImageF image = project_image(*op_, truth(), 1000.f);
  for (float& p : image.pixels) p = std::round(p);  // integer counts, as a sensor records them
  const std::span<const float> pixels(image.pixels.data(), image.pixels.size());
  EXPECT_EQ(dark_floor_of(pixels, 0.f), 0.5f);
  EXPECT_EQ(dark_floor_of(pixels, 3.f), 3.f);
  const std::vector<float> unlit(64, 0.f);
  EXPECT_GT(dark_floor_of(unlit, 0.f), 1e29f);

  MartSettings s;
  s.iterations = 3;
  const MartResult own = reconstruct(*op_, image, s);
  EXPECT_EQ(own.skipped.dark_floor, 0.5f);
  s.dark_floor = 0.5f;
  const MartResult given = reconstruct(*op_, image, s);
  EXPECT_EQ(given.skipped.dark_floor, 0.5f);
  EXPECT_TRUE(std::equal(own.volume.data.begin(), own.volume.data.end(), given.volume.data.begin()));
  s.dark_floor = 1e-6f;
  const MartResult lower = reconstruct(*op_, image, s);
  EXPECT_EQ(lower.skipped.dark_floor, 1e-6f);
  EXPECT_FALSE(std::equal(own.volume.data.begin(), own.volume.data.end(), lower.volume.data.begin()))
      << "the floor enters every dark pixel's ratio";

  for (const float bad : {-1.f, std::nanf(""), std::numeric_limits<float>::infinity()}) {
    s.dark_floor = bad;
    const auto problem = check(s);
    ASSERT_TRUE(problem) << bad;
    EXPECT_EQ(problem->key, "dark_floor");
  }
}

// The dark cutoff's selection against its definition, voxel by voxel (the selection tests it
// with row bitsets): a voxel is dark when a dark pixel lies where both its column weight and its
// row weight exceed the cutoff's fraction of their largest values.
TEST_F(Mart, DarkCutoffSkipsExactlyTheVoxelsItsDefinitionNames) {
  const ImageF image = project_image(*op_, truth(), 1000.f);
  const Grid3& g = op_->grid();
  for (const double cutoff : {0.0, 0.5, 0.9}) {
    MartSettings s;
    s.noise_threshold = 0.01f;
    s.dark_weight_cutoff = cutoff;
    s.iterations = 1;
    const MartResult r = reconstruct(*op_, image, s);
    auto dark = [&](int column, int row) {
      const std::size_t i = std::size_t(row) * std::size_t(image.width) + std::size_t(column);
      return op_->white().pixels[i] > 0.f && !(image.pixels[i] > s.noise_threshold);
    };
    auto cut_of = [&](const AxisWeights& a) {
      float peak = 0.f;
      for (int p = a.first; p <= a.last; ++p) peak = std::max(peak, a.at(p));
      return float(cutoff) * peak;
    };
    std::size_t expected = 0;
    for (int z = 0; z < g.shape[2]; ++z) {
      for (int y = 0; y < g.shape[1]; ++y) {
        for (int x = 0; x < g.shape[0]; ++x) {
          const std::size_t v = g.index(x, y, z);
          if (!(op_->normaliser(v) > 0.f)) continue;
          const AxisWeights ax = op_->x_weights(z, x), ay = op_->y_weights(z, y);
          const float cx = cut_of(ax), cy = cut_of(ay);
          bool seen_dark = false;
          for (int row = ay.first; row <= ay.last && !seen_dark; ++row) {
            if (!(ay.at(row) > cy)) continue;
            for (int column = ax.first; column <= ax.last && !seen_dark; ++column) {
              seen_dark = ax.at(column) > cx && dark(column, row);
            }
          }
          if (!seen_dark) continue;
          ++expected;
          EXPECT_EQ(r.volume.data[v], 0.f) << "voxel " << v;
        }
      }
    }
    std::cout << "measured: cutoff " << cutoff << ": dark voxels " << expected << ", active " << r.skipped.voxels_active
              << "\n";
    EXPECT_EQ(r.skipped.voxels_dark, expected) << "cutoff " << cutoff;
    EXPECT_GT(expected, 0u);
    EXPECT_GT(r.skipped.voxels_active, 0u);
  }
}

TEST_F(Mart, RegionOfInterestLimitsTheSolution) {
  const ImageF image = project_image(*op_, truth(), 1000.f);
  MartSettings s;
  s.region = RegionMm{{-10, -10, -0.5}, {10, 10, 0.5}};  // the z = 0 slice only
  const MartResult r = reconstruct(*op_, image, s);
  EXPECT_EQ(r.skipped.slices_empty, 8);
  for (int z = 0; z < 9; ++z) {
    if (z == 4) continue;
    for (int y = 0; y < 10; ++y) {
      for (int x = 0; x < 10; ++x) EXPECT_EQ(r.volume.at(x, y, z), 0.f);
    }
  }
}

TEST_F(Mart, ConvergenceStopEndsEarly) {
  const ImageF image = project_image(*op_, truth(), 1000.f);
  MartSettings s;
  s.iterations = 200;
  s.convergence = 0.01;
  const MartResult r = reconstruct(*op_, image, s);
  EXPECT_TRUE(r.converged);
  EXPECT_LT(r.iterations.size(), 200u);
}

// Without the final residual's projection the volume is the same, only the report is missing.
TEST_F(Mart, FinalResidualOffLeavesTheVolumeAsItWas) {
  const ImageF image = project_image(*op_, truth(), 1000.f);
  for (bool accelerate : {false, true}) {
    MartSettings s;
    s.iterations = 4;
    s.accelerate = accelerate;
    const MartResult with = reconstruct(*op_, image, s);
    s.final_residual = false;
    const MartResult without = reconstruct(*op_, image, s);
    ASSERT_TRUE(with.final_residual);
    EXPECT_GT(*with.final_residual, 0.0);
    EXPECT_FALSE(without.final_residual);
    EXPECT_EQ(with.volume.data, without.volume.data) << "accelerated " << accelerate;
    ASSERT_EQ(with.iterations.size(), without.iterations.size());
    for (std::size_t k = 0; k < with.iterations.size(); ++k) {
      EXPECT_EQ(with.iterations[k].residual, without.iterations[k].residual);
    }
  }
}

// Parameters: accelerated; the sensor blur's sigma, mm.
class MartStable : public Mart, public ::testing::WithParamInterface<std::tuple<bool, double>> {};

TEST_P(MartStable, OnExtremeInputs) {
  const Volume exact = truth();
  MartSettings s;
  s.iterations = 50;
  s.mu = 1.0;
  s.accelerate = std::get<0>(GetParam());
  s.sensor_blur_sigma_mm = std::get<1>(GetParam());
  const float bound = 1e30f;
  {  // all zero: nothing to reconstruct
    const MartResult r = reconstruct(*op_, ImageF(850, 850, 0.f), s);
    EXPECT_TRUE(all_finite_bounded(r.volume, 0.f));
    EXPECT_EQ(r.skipped.voxels_active, 0u);
  }
  {  // saturated 16-bit
    const MartResult r = reconstruct(*op_, ImageF(850, 850, 65535.f), s);
    EXPECT_TRUE(all_finite_bounded(r.volume, bound));
    ASSERT_TRUE(r.final_residual);
    EXPECT_TRUE(std::isfinite(*r.final_residual));
  }
  {  // one hot pixel on a blob image
    ImageF image = project_image(*op_, exact, 1000.f);
    image.at(425, 425) = 65535.f;
    const MartResult r = reconstruct(*op_, image, s);
    EXPECT_TRUE(all_finite_bounded(r.volume, bound));
  }
  {  // a hot pixel alone in the dark
    ImageF image(850, 850, 0.f);
    image.at(425, 425) = 65535.f;
    const MartResult r = reconstruct(*op_, image, s);
    EXPECT_TRUE(all_finite_bounded(r.volume, bound));
  }
  {  // near the float limits, high and low: the same shape as at ordinary scale
    const MartResult ordinary = reconstruct(*op_, project_image(*op_, exact, 1000.f), s);
    for (float scale : {1e29f, 1e-25f}) {
      const MartResult r = reconstruct(*op_, project_image(*op_, exact, scale), s);
      EXPECT_TRUE(all_finite_bounded(r.volume, bound)) << scale;
      EXPECT_GT(quality_factor(r.volume, ordinary.volume), 0.99) << scale;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(PlainAndAcceleratedWithAndWithoutBlur, MartStable,
                         ::testing::Combine(::testing::Bool(), ::testing::Values(0.0, 0.0052)));

TEST_F(Mart, RejectsNaNAndNegativePixelsAndBadSettings) {
  ImageF image(850, 850, 1.f);
  image.at(3, 4) = std::nanf("");
  try {
    reconstruct(*op_, image, MartSettings{});
    FAIL() << "NaN accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("pixel (3, 4)"), std::string::npos) << e.what();
  }
  image.at(3, 4) = -1.f;
  EXPECT_THROW(reconstruct(*op_, image, MartSettings{}), InputError);
  EXPECT_THROW(reconstruct(*op_, ImageF(10, 10, 1.f), MartSettings{}), InputError);
  MartSettings bad;
  bad.mu = 1.5;
  EXPECT_THROW(reconstruct(*op_, ImageF(850, 850, 1.f), bad), InputError);
  // A setting out of its range is refused naming its key.
  const auto expect_refused = [&](const MartSettings& s, const std::string& key) {
    try {
      reconstruct(*op_, ImageF(850, 850, 1.f), s);
      ADD_FAILURE() << key << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  };
  for (const double blur : {-0.001, std::nan(""), 0.06}) {
    MartSettings blurred;
    blurred.sensor_blur_sigma_mm = blur;
    expect_refused(blurred, "sensor_blur_sigma_mm");
  }
  for (const double threshold : {-0.001, std::nan(""), 1.0}) {
    MartSettings pruned;
    pruned.prune_threshold = threshold;
    expect_refused(pruned, "prune_threshold");
  }
  for (const int reach : {-1, kMaxPruneDepthReach + 1}) {
    MartSettings pruned;
    pruned.prune_depth_reach = reach;
    expect_refused(pruned, "prune_depth_reach");
  }
  for (const double threshold : {-0.001, std::nan(""), 1.0}) {
    MartSettings pruned;
    pruned.prune_local_threshold = threshold;
    expect_refused(pruned, "prune_local_threshold");
  }
  for (const double power : {0.999, std::nan(""), kMaxMlosPower + 0.001}) {
    MartSettings sharp;
    sharp.mlos_power = power;
    expect_refused(sharp, "mlos_power");
  }
  MartSettings ones_raised;  // a power without the start it raises: refused, not ignored
  ones_raised.start = MartStart::ones;
  ones_raised.mlos_power = 2;
  expect_refused(ones_raised, "mlos_power");
}

// The MLOS start takes a dark pixel at the floor (half the faintest lit pixel here), which scales
// with the image, and n_j = Σ W white, so the start, and with it every iteration, scales with the
// image: a camera's units (12-bit counts, 16-bit, a float image in 0..1) change no particle.
TEST_F(Mart, TheVolumeScalesWithTheImage) {
  // The particles' faint fringes dark (below 5 % of the peak), so that active voxels see dark
  // pixels beside lit ones.
  ImageF image = project_image(*op_, truth(), 1000.f);
  const float image_peak = *std::max_element(image.pixels.begin(), image.pixels.end());
  for (float& v : image.pixels) v = v < 0.05f * image_peak ? 0.f : v;
  MartSettings s;
  s.iterations = 3;
  const Volume reference = reconstruct(*op_, image, s).volume;
  double peak = 0;
  for (float v : reference.data) peak = std::max(peak, double(v));
  ASSERT_GT(peak, 0);
  for (const float c : {1e-3f, 16.f}) {
    ImageF scaled = image;
    for (float& v : scaled.pixels) v *= c;
    const Volume volume = reconstruct(*op_, scaled, s).volume;
    double worst = 0;
    for (std::size_t j = 0; j < volume.data.size(); ++j)
      worst = std::max(worst, std::abs(double(volume.data[j]) / c - double(reference.data[j])) / peak);
    std::cout << "measured: image x " << c << ", largest difference of volume / " << c << " " << worst
              << " of the peak\n";
    EXPECT_LT(worst, 1e-5) << "image x " << c;
  }
}

TEST_F(Mart, IdenticalVolumesAtOneAndTwoThreads) {
  const ImageF image = project_image(*op_, truth(), 1000.f);
  for (const bool accelerate : {false, true}) {
    for (const double blur : {0.0, 0.0052}) {
      MartSettings s;
      s.iterations = 5;
      s.accelerate = accelerate;
      s.sensor_blur_sigma_mm = blur;
      s.prune_threshold = accelerate ? 1e-2 : 0.0;  // the pruned active sets, laid out again
      s.prune_scope = blur > 0 ? PruneScope::slice : PruneScope::volume;
      s.prune_local_threshold = accelerate && blur > 0 ? 5e-2 : 0.0;  // and the neighbourhoods' peaks
      s.mlos_power = accelerate ? 3.0 : 1.0;                          // its peak found in parallel
      auto run = [&](int threads) {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        const WeightingOperator op = make_operator(*camera_, op_->grid());
        return reconstruct(op, image, s).volume.data;
      };
      const auto one = run(1), two = run(2);
      ASSERT_EQ(one.size(), two.size());
      EXPECT_EQ(0, std::memcmp(one.data(), two.data(), one.size() * sizeof(float)))
          << "accelerated " << accelerate << ", blur " << blur;
    }
  }
}

// The value-adaptive active set (MartSettings::prune). MART's update is multiplicative, so a
// voxel at exactly 0 stays 0, and leaving it out of the passes changes no bit: pruning with
// threshold 0 against no pruning, over the plain, accelerated and blurred iterations. Exact
// zeros come from values flushed below recon's smallest float: here the pixels between the
// particles' images read 1e-20 instead of 0, so the voxels that see only them are driven down
// by the clamped log-ratios until they flush, and the active set is laid out again.
TEST_F(Mart, PruningExactZerosGivesTheBitsOfNoPruning) {
  // A box wide enough (5 mm) that most voxels see none of the three particles.
  const WeightingOperator op = make_operator(*camera_, centred_grid(40, 9, 1.0, -4.0));
  ImageF image = project_image(op, blob_volume(op.grid(), {{8, 9, 2}, {11, 11, 4.5}, {9, 12, 7}}, 0.7, 0.7), 1000.f);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    if (op.white().pixels[i] > 0.f && image.pixels[i] < 2e-30f) image.pixels[i] = 2e-30f;
  }
  for (const bool accelerate : {false, true}) {
    for (const double blur : {0.0, 0.0052}) {
      MartSettings s;
      s.iterations = 20;
      s.mu = 1;
      s.accelerate = accelerate;
      s.sensor_blur_sigma_mm = blur;
      s.prune = false;
      const MartResult off = reconstruct(op, image, s);
      s.prune = true;
      const MartResult zeros = reconstruct(op, image, s);
      const std::string what = std::string(accelerate ? "accelerated" : "plain") + ", blur " + std::to_string(blur);
      ASSERT_EQ(off.volume.data.size(), zeros.volume.data.size());
      EXPECT_EQ(0,
                std::memcmp(off.volume.data.data(), zeros.volume.data.data(), off.volume.data.size() * sizeof(float)))
          << what;
      ASSERT_EQ(off.iterations.size(), zeros.iterations.size()) << what;
      for (std::size_t i = 0; i < off.iterations.size(); ++i) {
        EXPECT_EQ(off.iterations[i].residual, zeros.iterations[i].residual) << what << ", iteration " << i;
      }
      EXPECT_EQ(off.final_residual, zeros.final_residual) << what;
      // The report adds up; pruning happened where values flushed to 0 (the accelerated and the
      // blurred runs; the plain unblurred one keeps every voxel above 1e-30 for 20 iterations).
      EXPECT_EQ(off.skipped.voxels_pruned, 0u);
      if (accelerate || blur > 0) {
        EXPECT_GT(zeros.skipped.voxels_pruned, 0u) << what;
        EXPECT_GT(zeros.skipped.fraction_updates_skipped(), off.skipped.fraction_updates_skipped()) << what;
        EXPECT_LT(zeros.skipped.work_done, off.skipped.work_done) << what;
      }
      std::size_t updates = 0;
      for (std::size_t i = 0; i < zeros.iterations.size(); ++i) {
        updates += zeros.iterations[i].live_voxels;
        if (i) {
          EXPECT_LE(zeros.iterations[i].live_voxels, zeros.iterations[i - 1].live_voxels) << what;
        }
        EXPECT_EQ(off.iterations[i].live_voxels, off.skipped.voxels_active) << what;
      }
      EXPECT_EQ(updates, zeros.skipped.voxel_updates) << what;
      EXPECT_EQ(off.skipped.voxel_updates, off.skipped.voxels_active * off.iterations.size()) << what;
      std::cout << "measured: " << what << ": " << zeros.skipped.voxels_pruned << " of " << zeros.skipped.voxels_active
                << " active voxels pruned, voxel updates skipped " << zeros.skipped.fraction_updates_skipped()
                << " (without pruning " << off.skipped.fraction_updates_skipped() << ")\n";
    }
  }
}

// A threshold above 0 drops faint voxels that might still have grown: an approximation. On the
// three-particle scene, 10 accelerated iterations: Q* and the volume stay close to the unpruned
// ones, and the passes skip voxels. Bounds from measurement (the assertion messages print it).
TEST_F(Mart, PruningAtASmallThresholdStaysCloseToNoPruning) {
  const Volume exact = truth();
  const ImageF image = project_image(*op_, exact, 1000.f);
  MartSettings s;
  s.iterations = 10;
  s.mu = 1;
  s.accelerate = true;
  s.prune = false;
  const MartResult off = reconstruct(*op_, image, s);
  const double q_off = quality_factor(off.volume, exact);
  for (const double threshold : {1e-3, 1e-2}) {
    s.prune = true;
    s.prune_threshold = threshold;
    const MartResult pruned = reconstruct(*op_, image, s);
    const double q = quality_factor(pruned.volume, exact);
    double diff = 0, norm = 0;
    for (std::size_t i = 0; i < off.volume.data.size(); ++i) {
      const double d = double(pruned.volume.data[i]) - off.volume.data[i];
      diff += d * d;
      norm += double(off.volume.data[i]) * off.volume.data[i];
    }
    const double relative = std::sqrt(diff / norm);
    std::cout << "measured: prune threshold " << threshold << ": Q* " << q << " (unpruned " << q_off
              << "), volume differs by " << relative << " (relative L2), voxel updates skipped "
              << pruned.skipped.fraction_updates_skipped() << " (unpruned " << off.skipped.fraction_updates_skipped()
              << ")\n";
    // The same Q* within 0.01; the volumes differ mostly in the faint voxels the threshold removed.
    EXPECT_NEAR(q, q_off, 0.01) << "threshold " << threshold << ": Q* " << q << " against " << q_off;
    EXPECT_LT(relative, 0.08) << "threshold " << threshold << " (measured 0.044, 0.056)";
    EXPECT_GT(pruned.skipped.voxels_pruned, 0u) << "threshold " << threshold;
    EXPECT_GT(pruned.skipped.fraction_updates_skipped(), off.skipped.fraction_updates_skipped());
    EXPECT_TRUE(all_finite_bounded(pruned.volume, 1e30f));
  }
}

// The image of a particle at `bright` (voxel coordinates of op's grid) and one 30 times fainter at
// `faint`.
ImageF bright_and_faint(const WeightingOperator& op, const std::array<double, 3>& bright,
                        const std::array<double, 3>& faint) {
  ImageF image = project_image(op, blob_volume(op.grid(), {bright}, 0.7, 0.7), 1000.f);
  const ImageF dim = project_image(op, blob_volume(op.grid(), {faint}, 0.7, 0.7), 1000.f / 30.f);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] += dim.pixels[i];
  return image;
}

// MartSettings::prune_scope: the threshold is a fraction of the volume's peak, or of each depth
// slice's. A bright particle at z = -2 mm and one 30 times fainter at z = +3 mm, apart in x, and a
// threshold of 0.1: against the volume's peak the faint particle is pruned at the start, against
// its own slice's it is reconstructed. Either way every voxel left is above the threshold times its
// reference peak (the last prune follows the last update).
TEST_F(Mart, PruningAgainstEachDepthSlicesPeakKeepsAFaintParticleAwayFromABrightOne) {
  const WeightingOperator op = make_operator(*camera_, centred_grid(40, 9, 1.0, -4.0));
  const Grid3& g = op.grid();
  const ImageF image = bright_and_faint(op, {10, 20, 2}, {30, 20, 7});
  MartSettings s;
  s.iterations = 10;
  s.mu = 1;
  s.accelerate = true;
  s.prune_threshold = 0.1;
  const std::size_t slice = std::size_t(g.shape[0]) * g.shape[1];
  std::array<double, 2> near_faint{};  // intensity within 2 voxels of the faint particle
  for (const PruneScope scope : {PruneScope::volume, PruneScope::slice}) {
    s.prune_scope = scope;
    const MartResult r = reconstruct(op, image, s);
    const HugePageVector<float>& e = r.volume.data;
    const float volume_peak = *std::max_element(e.begin(), e.end());
    for (int z = 0; z < g.shape[2]; ++z) {
      const auto first = e.begin() + std::ptrdiff_t(z * slice), end = first + std::ptrdiff_t(slice);
      const float reference = scope == PruneScope::slice ? *std::max_element(first, end) : volume_peak;
      const float cut = float(s.prune_threshold * double(reference));
      EXPECT_EQ(0, std::count_if(first, end, [&](float v) { return v != 0.f && v <= cut; }))
          << "slice " << z << ", scope " << int(scope) << ": live voxels at or below the threshold";
    }
    for (int z = 5; z <= 8; ++z)
      for (int y = 18; y <= 22; ++y)
        for (int x = 28; x <= 32; ++x) near_faint[int(scope)] += r.volume.at(x, y, z);
    std::cout << "measured: scope " << int(scope) << ": intensity near the faint particle " << near_faint[int(scope)]
              << ", voxel updates skipped " << r.skipped.fraction_updates_skipped() << "\n";
    EXPECT_GT(r.skipped.voxels_pruned, 0u);
  }
  EXPECT_EQ(near_faint[0], 0.0) << "the volume's peak: the faint particle is below 0.1 of it";
  EXPECT_GT(near_faint[1], 0.0) << "its slice's peak: the faint particle is kept";
}

// MartSettings::prune_local_threshold: a bright particle and one 30 times fainter in the same
// depth slice, 27 voxels apart in x (further than a neighbourhood's 12). A cut of 0.1 of the
// slice's peak prunes the faint particle whole; the same fraction of each voxel's neighbourhood's
// peak, over a cut of 1e-2 of the slice's, keeps it (it is its own neighbourhood's peak) and still
// prunes more voxels than 1e-2 alone. Every voxel left is above both cuts, the neighbourhood's
// peak taken here from the result over kLocalPruneBrick's bricks about the voxel's.
TEST_F(Mart, PruningAgainstTheNeighbourhoodsPeakKeepsAFaintParticleBesideABrightOne) {
  const WeightingOperator op = make_operator(*camera_, centred_grid(40, 9, 1.0, -4.0));
  const Grid3& g = op.grid();
  const ImageF image = bright_and_faint(op, {6, 20, 4}, {33, 20, 4});
  MartSettings s;
  s.iterations = 10;
  s.mu = 1;
  s.accelerate = true;
  s.prune_scope = PruneScope::slice;
  struct Case {
    double slice_cut, local_cut;
    double near_faint = 0;
    std::size_t live = 0;
  };
  std::array<Case, 3> cases{Case{0.1, 0.0}, Case{1e-2, 0.0}, Case{1e-2, 0.1}};
  const std::size_t slice = std::size_t(g.shape[0]) * g.shape[1];
  const auto [bx, by, bz] = kLocalPruneBrick;
  for (Case& c : cases) {
    s.prune_threshold = c.slice_cut;
    s.prune_local_threshold = c.local_cut;
    const MartResult r = reconstruct(op, image, s);
    const HugePageVector<float>& e = r.volume.data;
    for (int z = 0; z < g.shape[2]; ++z) {
      const auto first = e.begin() + std::ptrdiff_t(z * slice);
      const float slice_peak = *std::max_element(first, first + std::ptrdiff_t(slice));
      for (int y = 0; y < g.shape[1]; ++y)
        for (int x = 0; x < g.shape[0]; ++x) {
          const float v = r.volume.at(x, y, z);
          if (v == 0.f) continue;
          ++c.live;
          float near_peak = 0.f;  // over the bricks about (x, y, z)'s
          for (int zz = std::max(0, (z / bz - 1) * bz); zz < std::min(g.shape[2], (z / bz + 2) * bz); ++zz)
            for (int yy = std::max(0, (y / by - 1) * by); yy < std::min(g.shape[1], (y / by + 2) * by); ++yy)
              for (int xx = std::max(0, (x / bx - 1) * bx); xx < std::min(g.shape[0], (x / bx + 2) * bx); ++xx)
                near_peak = std::max(near_peak, r.volume.at(xx, yy, zz));
          const float cut = std::max(float(c.slice_cut * double(slice_peak)), float(c.local_cut * double(near_peak)));
          EXPECT_GT(v, cut) << "cuts " << c.slice_cut << " / " << c.local_cut << ": voxel (" << x << ", " << y << ", "
                            << z << ") left at or below its cut";
        }
    }
    for (int z = 2; z <= 6; ++z)
      for (int y = 18; y <= 22; ++y)
        for (int x = 31; x <= 35; ++x) c.near_faint += r.volume.at(x, y, z);
    std::cout << "measured: slice cut " << c.slice_cut << ", neighbourhood cut " << c.local_cut
              << ": intensity near the faint particle " << c.near_faint << ", live voxels " << c.live
              << ", voxel updates skipped " << r.skipped.fraction_updates_skipped() << "\n";
  }
  EXPECT_EQ(cases[0].near_faint, 0.0) << "0.1 of the slice's peak: the faint particle is pruned";
  EXPECT_GT(cases[2].near_faint, 0.5 * cases[1].near_faint)
      << "0.1 of its neighbourhood's peak: the faint particle stays";
  EXPECT_LT(cases[2].live, cases[1].live) << "the neighbourhood's cut prunes more than 1e-2 of the slice's peak alone";
}

// MartSettings::mlos_power: the MLOS start raised to P, then scaled to the image's light. One
// iteration at a relaxation so small that every update's factor rounds to 1 leaves the start as it
// is: at P = 2 it is P = 1's squared, voxel by voxel up to one factor, with the image's light; at
// P = 4 an image a million times brighter gives the same start a million times brighter (ln E less
// its peak first: no exponent reaches the clamp, which a plain exp(4 ln E) would pass). And with a
// cut against the neighbourhood's peak after it, P = 3 leaves MART's first iteration fewer voxels.
TEST_F(Mart, TheMlosStartRaisedToAPowerIsThatPowerScaledToTheImagesLight) {
  const WeightingOperator op = make_operator(*camera_, centred_grid(40, 9, 1.0, -4.0));
  const ImageF image = project_image(op, blob_volume(op.grid(), {{20, 20, 4}, {10, 12, 5}}, 0.7, 0.7), 1000.f);
  MartSettings s;
  s.iterations = 1;
  s.mu = 1e-9;  // |mu x update| < 1e-7: exp rounds to 1
  s.prune = false;
  const auto start = [&](double power, const ImageF& frame) {
    s.mlos_power = power;
    return reconstruct(op, frame, s).volume;
  };
  const Volume one = start(1, image), two = start(2, image);
  const float peak_one = *std::max_element(one.data.begin(), one.data.end());
  double light = 0, image_light = 0;
  for (const float v : two.data) light += v;
  for (const float v : image.pixels) image_light += v;
  EXPECT_NEAR(light, image_light, 1e-4 * image_light);
  std::size_t index_of_peak = std::size_t(std::max_element(one.data.begin(), one.data.end()) - one.data.begin());
  const double factor = double(two.data[index_of_peak]) / (double(peak_one) * peak_one);
  std::size_t compared = 0;
  for (std::size_t j = 0; j < one.data.size(); ++j) {
    if (one.data[j] <= 1e-3f * peak_one) continue;
    ++compared;
    EXPECT_NEAR(double(two.data[j]), factor * double(one.data[j]) * one.data[j], 1e-4 * double(two.data[j]))
        << "voxel " << j;
  }
  EXPECT_GT(compared, 100u);

  ImageF bright = image;
  for (float& v : bright.pixels) v *= 1e6f;
  const Volume four = start(4, image), four_bright = start(4, bright);
  const float peak_four = *std::max_element(four.data.begin(), four.data.end());
  for (std::size_t j = 0; j < four.data.size(); ++j) {
    if (four.data[j] <= 1e-6f * peak_four) continue;
    EXPECT_NEAR(double(four_bright.data[j]) * 1e-6, double(four.data[j]), 1e-4 * double(four.data[j]))
        << "voxel " << j << ": the start depends on the image's units";
  }

  s.iterations = 2;
  s.mu = 1;
  s.prune = true;
  s.prune_scope = PruneScope::slice;
  s.prune_threshold = 1e-3;
  s.prune_local_threshold = 0.1;
  std::array<std::size_t, 2> first_live{};
  for (const double power : {1.0, 3.0}) {
    s.mlos_power = power;
    const MartResult r = reconstruct(op, image, s);
    ASSERT_FALSE(r.iterations.empty());
    first_live[power > 1] = r.iterations.front().live_voxels;
  }
  std::cout << "measured: voxels MART's first iteration updates, start at power 1 / 3: " << first_live[0] << " / "
            << first_live[1] << "\n";
  EXPECT_LT(first_live[1], first_live[0]) << "a sharper start left the first iteration as many voxels";
}

// MartSettings::prune_depth_reach: a voxel at or below its slice's cut stays while a voxel within
// `reach` slices of it along depth (same x, y) is above theirs. On one particle with a high
// threshold of the volume's peak (its faint depth ends are below it): every live voxel of the
// result is above the cut or that near one, some are kept only by the reach, and the particle
// keeps more of its depth extent than with the threshold alone.
TEST_F(Mart, ADepthReachKeepsTheFaintDepthEndsOfAParticle) {
  const WeightingOperator op = make_operator(*camera_, centred_grid(40, 9, 1.0, -4.0));
  const Grid3& g = op.grid();
  const ImageF image = project_image(op, blob_volume(g, {{20, 20, 4}}, 0.7, 0.7), 1000.f);
  MartSettings s;
  s.iterations = 6;
  s.mu = 1;
  s.prune_threshold = 0.3;
  const std::size_t slice = std::size_t(g.shape[0]) * g.shape[1];
  std::array<std::size_t, 2> live{};
  for (const int reach : {0, 2}) {
    s.prune_depth_reach = reach;
    const MartResult r = reconstruct(op, image, s);
    const HugePageVector<float>& e = r.volume.data;
    const float cut = float(s.prune_threshold * double(*std::max_element(e.begin(), e.end())));
    std::size_t kept_by_reach = 0;
    for (int z = 0; z < g.shape[2]; ++z)
      for (std::size_t column = 0; column < slice; ++column) {
        const float v = e[z * slice + column];
        if (v == 0.f) continue;
        ++live[reach > 0];
        if (v > cut) continue;
        bool near = false;
        for (int zz = std::max(0, z - reach); zz <= std::min(g.shape[2] - 1, z + reach); ++zz)
          near = near || e[zz * slice + column] > cut;
        EXPECT_TRUE(near) << "reach " << reach << ": voxel " << column << " of slice " << z
                          << " is at or below the cut with no voxel above within reach";
        kept_by_reach += near;
      }
    if (reach > 0) {
      EXPECT_GT(kept_by_reach, 0u) << "the reach kept no voxel below the cut";
    }
    EXPECT_GT(r.skipped.voxels_pruned, 0u) << "reach " << reach;
  }
  EXPECT_GT(live[1], live[0]) << "the reach keeps more of the particle";
}

// A caller cancels by throwing plenopiv::Cancelled from the progress callback (what the daemon
// does when a run stops): the reconstruction stops there, and the workspace is free: the next
// reconstruction in it has the bits of one without a workspace, pruning's smaller active set
// included.
TEST_F(Mart, CancellingFromProgressStopsAndFreesTheWorkspace) {
  const ImageF image = project_image(*op_, truth(), 1000.f);
  MartSettings s;
  s.iterations = 6;
  s.accelerate = true;
  s.prune_threshold = 1e-2;
  MartWorkspace workspace;
  int last = 0;
  EXPECT_THROW(reconstruct(*op_, image, s, workspace,
                           [&](const IterationReport& it) {
                             last = it.iteration;
                             if (it.iteration == 2) throw plenopiv::Cancelled("run stopping");
                           }),
               plenopiv::Cancelled);
  EXPECT_EQ(last, 2);
  const MartResult again = reconstruct(*op_, image, s, workspace);
  const MartResult fresh = reconstruct(*op_, image, s);
  EXPECT_EQ(0,
            std::memcmp(again.volume.data.data(), fresh.volume.data.data(), fresh.volume.data.size() * sizeof(float)));
}

// A kept workspace changes no bit: images of different scenes (and an empty one) in sequence, then
// the first again, each against its reconstruction without a workspace; the plain iteration and
// the accelerated, blurred one (which uses every buffer).
TEST_F(Mart, WorkspaceReuseGivesTheBitsOfAFreshReconstruction) {
  const ImageF a = project_image(*op_, truth(), 1000.f);
  const ImageF b =
      project_image(*op_, blob_volume(op_->grid(), {{2, 2, 1}, {7, 3, 6}, {5, 8, 3}, {8, 8, 8}}, 0.9, 0.6), 700.f);
  const ImageF dark(850, 850, 0.f);
  for (const bool accelerate : {false, true}) {
    MartSettings s;
    s.iterations = 4;
    s.accelerate = accelerate;
    s.sensor_blur_sigma_mm = accelerate ? 0.0052 : 0.0;
    MartWorkspace workspace;
    std::size_t bytes_after_b = 0;
    int k = 0;
    for (const ImageF* image : {&a, &b, &dark, &a}) {
      const MartResult fresh = reconstruct(*op_, *image, s);
      const MartResult kept = reconstruct(*op_, *image, s, workspace);
      ASSERT_EQ(fresh.volume.data.size(), kept.volume.data.size());
      EXPECT_EQ(
          0, std::memcmp(fresh.volume.data.data(), kept.volume.data.data(), fresh.volume.data.size() * sizeof(float)))
          << "frame " << k << ", accelerated " << accelerate;
      EXPECT_EQ(fresh.final_residual, kept.final_residual) << "frame " << k;
      EXPECT_EQ(fresh.skipped.voxels_active, kept.skipped.voxels_active) << "frame " << k;
      ASSERT_EQ(fresh.iterations.size(), kept.iterations.size());
      for (std::size_t i = 0; i < fresh.iterations.size(); ++i) {
        EXPECT_EQ(fresh.iterations[i].residual, kept.iterations[i].residual) << "frame " << k << ", iteration " << i;
      }
      if (k == 1) bytes_after_b = workspace.bytes();
      ++k;
    }
    // The frames after B needed no more than A and B: the buffers were kept, not grown.
    EXPECT_GT(bytes_after_b, 4 * 850 * 850 * sizeof(float));
    EXPECT_EQ(workspace.bytes(), bytes_after_b);
  }
}

// One workspace for operators of different sensors and grids, larger after smaller and back:
// the buffers are sized for each call, and the volumes are those without a workspace.
TEST_F(Mart, WorkspaceServesOperatorsOfOtherSensorsAndGrids) {
  // 40 x 30 lenses on a 680 x 510 sensor, otherwise the small camera.
  const optics::CameraModel cam = optics::parse_camera_yaml(
      "sensor:    {width_px: 680, height_px: 510, pixel_pitch_mm: 0.0074}\n"
      "microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 40, count_y: 30, layout: rect}\n"
      "main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}\n",
      "test camera");
  const WeightingOperator other = make_operator(cam, centred_grid(14, 7, 1.0, -3.0));
  const ImageF big = project_image(*op_, truth(), 1000.f);
  const ImageF small = project_image(other, blob_volume(other.grid(), {{4, 5, 2}, {9, 8, 4}}, 0.8, 0.7), 1000.f);
  MartSettings s;
  s.iterations = 3;
  MartWorkspace workspace;
  int k = 0;
  using Call = std::pair<const WeightingOperator*, const ImageF*>;
  for (const auto& [op, image] : {Call{op_, &big}, Call{&other, &small}, Call{op_, &big}}) {
    const Volume fresh = reconstruct(*op, *image, s).volume;
    const Volume kept = reconstruct(*op, *image, s, workspace).volume;
    ASSERT_EQ(fresh.data.size(), kept.data.size());
    EXPECT_EQ(0, std::memcmp(fresh.data.data(), kept.data.data(), fresh.data.size() * sizeof(float))) << "call " << k;
    EXPECT_GT(*std::max_element(kept.data.begin(), kept.data.end()), 0.f) << "call " << k;
    ++k;
  }
  // An image that is not the operator's sensor is refused as without a workspace.
  EXPECT_THROW(reconstruct(other, big, s, workspace), InputError);
}

// A workspace serves one reconstruction at a time: a second one started while the first runs
// (here from its progress callback) is refused as a programming error (std::logic_error, not the
// bad-input InputError), and the first is unharmed; a moved-from workspace likewise.
TEST_F(Mart, WorkspaceInUseIsRefused) {
  const ImageF image = project_image(*op_, truth(), 1000.f);
  MartSettings s;
  s.iterations = 2;
  MartWorkspace workspace;
  int refused = 0;
  const MartResult r = reconstruct(*op_, image, s, workspace, [&](const IterationReport&) {
    try {
      reconstruct(*op_, image, s, workspace);
    } catch (const std::logic_error& e) {
      EXPECT_NE(std::string(e.what()).find("in use"), std::string::npos) << e.what();
      ++refused;
    }
  });
  EXPECT_EQ(refused, 2);
  const Volume fresh = reconstruct(*op_, image, s).volume;
  EXPECT_EQ(0, std::memcmp(fresh.data.data(), r.volume.data.data(), fresh.data.size() * sizeof(float)));
  // Free again once it returned.
  EXPECT_NO_THROW(reconstruct(*op_, image, s, workspace));
  MartWorkspace moved_to = std::move(workspace);
  EXPECT_THROW(reconstruct(*op_, image, s, workspace), std::logic_error);  // NOLINT(bugprone-use-after-move)
  EXPECT_NO_THROW(reconstruct(*op_, image, s, moved_to));
}

// ---------------------------------------------------------------------------------------------

TEST(Quality, FactorOfKnownVolumes) {
  const Grid3 g = centred_grid(8, 8, 0.125, 0);
  const Volume a = blob_volume(g, {{3, 3, 3}}, 1, 1);
  Volume neg = a, flat(g, 2.f);
  for (float& v : neg.data) v = -v;
  EXPECT_NEAR(quality_factor(a, a), 1.0, 1e-12);
  EXPECT_NEAR(quality_factor(neg, a), -1.0, 1e-12);
  EXPECT_EQ(quality_factor(flat, a), 0.0);
  const Volume shifted = blob_volume(g, {{4, 3, 3}}, 1, 1);
  const double q = quality_factor(shifted, a);
  EXPECT_GT(q, 0.4);
  EXPECT_LT(q, 0.8);
}

TEST(Quality, GaussianFitFindsSubVoxelCentres) {
  const Grid3 g = centred_grid(16, 24, 0.125, -1.5);
  for (const std::array<double, 3> c : {std::array<double, 3>{7.3, 8.6, 11.2}, {5.0, 9.45, 14.8}}) {
    const Volume v = blob_volume(g, {c}, 1.0, 3.0);  // elongated in depth like a reconstruction
    const std::array<double, 3> guess{g.coordinate_mm(0, 7), g.coordinate_mm(1, 8), g.coordinate_mm(2, 12)};
    const auto fit = fit_particle(v, guess, {3, 3, 8});
    ASSERT_TRUE(fit);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(fit->position_voxel[a], c[a], 0.02) << "axis " << a;
  }
  EXPECT_FALSE(fit_particle(Volume(g, 0.f), {0, 0, 0}, {2, 2, 2}));
}

TEST(Quality, MomentsFitFindsBlobAndStreakCentres) {
  const Grid3 g = centred_grid(16, 24, 0.125, -1.5);
  const std::array<double, 3> guess{g.coordinate_mm(0, 7), g.coordinate_mm(1, 8), g.coordinate_mm(2, 12)};
  // A blob narrow across (the 3 x 3 window holds +-2 sigma) and long in depth (the window +-2.7
  // sigma): the windows' truncation pulls towards the peak voxel, by hundredths of a voxel.
  for (const std::array<double, 3> c : {std::array<double, 3>{7.3, 8.6, 11.2}, {7.0, 8.45, 13.8}}) {
    const auto fit = fit_particle_moments(blob_volume(g, {c}, 0.5, 3.0), guess, {3, 3, 8});
    ASSERT_TRUE(fit);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(fit->position_voxel[a], c[a], a == 2 ? 0.012 : 0.035) << "axis " << a;
    EXPECT_NEAR(fit->position_mm[2], g.coordinate_mm(2, 0) + c[2] * g.spacing_mm[2], 0.012 * g.spacing_mm[2]);
  }
  // A particle after many MART iterations: its light in three sharp voxels along a tilted line of
  // sight. The moments give their weighted mean; the fit through the peak's rows sees only the
  // brightest voxel (its neighbours are dark) and stays there.
  Volume streak(g, 0.f);
  streak.at(7, 8, 9) = 1.0f;
  streak.at(7, 9, 12) = 0.6f;
  streak.at(8, 9, 15) = 0.8f;
  const auto moments = fit_particle_moments(streak, guess, {3, 3, 8});
  ASSERT_TRUE(moments);
  EXPECT_NEAR(moments->position_voxel[0], (7 * 1.0 + 7 * 0.6 + 8 * 0.8) / 2.4, 1e-6);
  EXPECT_NEAR(moments->position_voxel[1], (8 * 1.0 + 9 * 0.6 + 9 * 0.8) / 2.4, 1e-6);
  EXPECT_NEAR(moments->position_voxel[2], (9 * 1.0 + 12 * 0.6 + 15 * 0.8) / 2.4, 1e-6);
  EXPECT_EQ(moments->peak, 1.0f);
  const auto rows = fit_particle(streak, guess, {3, 3, 8});
  ASSERT_TRUE(rows);
  EXPECT_EQ(rows->position_voxel[2], 9.0);
  // A voxel beyond lateral_radius of the peak is not counted.
  streak.at(10, 8, 9) = 5.0f;
  const auto with_neighbour = fit_particle_moments(streak, {g.coordinate_mm(0, 7), guess[1], guess[2]}, {1, 3, 8});
  ASSERT_TRUE(with_neighbour);
  EXPECT_NEAR(with_neighbour->position_voxel[2], moments->position_voxel[2], 1e-12);
  EXPECT_FALSE(fit_particle_moments(Volume(g, 0.f), {0, 0, 0}, {2, 2, 2}));
  EXPECT_THROW(fit_particle_moments(streak, guess, {3, 3, 8}, -1), InputError);
}

}  // namespace
}  // namespace plenopiv::recon

namespace plenopiv::recon {
namespace {

// Fig 16: the weights of one voxel against a ray-traced image of 400 point particles spread
// uniformly over that voxel, 10 000 rays each as the paper's, traced by core/sim (the product's
// simulator, sec 4). Zero-mean normalised cross-correlation over every pixel either of them
// lights. The weights are geometric (sec 5.2 has no diffraction), so the comparison is made with
// the simulator's diffraction jitter (its default, 5.2 um at the microlens plane and at the
// sensor) and without it, and with the jitter against the weights blurred by MART's sensor blur.
double fig16_ncc(const optics::CameraModel& cam, const optics::MicrolensArray& lenses, double z,
                 double diffraction_sigma_mm, double sensor_blur_mm = 0.0) {
  Grid3 g;
  g.shape = {1, 1, 1};
  g.spacing_mm = {0.125, 0.125, 0.125};
  g.origin_mm = {0.3, -0.2, z};
  const WeightingOperator op(cam, lenses, g, calib::geometric_white_image(cam, lenses));
  std::vector<float> weights(op.pixel_count());
  op.project(std::vector<float>{1.f}, weights);
  apply_sensor_blur(op, sensor_blur_mm, weights);
  std::mt19937 rng(16);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  std::vector<sim::Point3> particles;
  for (int p = 0; p < 400; ++p) particles.push_back({0.3 + 0.125 * u(rng), -0.2 + 0.125 * u(rng), z + 0.125 * u(rng)});
  sim::RenderOptions ro;
  ro.rays_per_particle = 10000;
  ro.diffraction_sigma_mm = diffraction_sigma_mm;
  const ImageF traced = sim::render(cam, lenses, particles, ro, 16).rays;
  double ma = 0, mb = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    if (weights[i] > 0 || traced.pixels[i] > 0) {
      ma += weights[i];
      mb += traced.pixels[i];
      ++n;
    }
  }
  ma /= double(n);
  mb /= double(n);
  double ab = 0, aa = 0, bb = 0;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    if (weights[i] > 0 || traced.pixels[i] > 0) {
      const double a = weights[i] - ma, b = traced.pixels[i] - mb;
      ab += a * b;
      aa += a * a;
      bb += b * b;
    }
  }
  const double ncc = ab / std::sqrt(aa * bb);
  std::cout << "measured: fig 16 NCC at z = " << z << " mm, diffraction " << diffraction_sigma_mm * 1000
            << " um, sensor blur model " << sensor_blur_mm * 1000 << " um: " << ncc << " over " << n << " pixels\n";
  return ncc;
}

TEST(WeightsFig16, OneVoxelResemblesRayTracedParticlesInIt) {
  const auto cam = small_camera();
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  const double diffraction_mm = sim::RenderOptions{}.diffraction_sigma_mm;
  for (double z : {-6.0, -2.0, 0.5, 3.0, 8.0}) {
    // Without diffraction the image is what the weights model.
    EXPECT_GE(fig16_ncc(cam, lenses, z, 0.0), 0.95) << "z = " << z << " (measured 0.974-0.997)";
    // With it, the 0.9 holds within 3 mm of focus. Far from focus each lens sees the
    // particles as a spot a few pixels wide, and the jitter (about 1 px of 7.4 um, microlens plane
    // and sensor together) spreads it over pixels the weights leave dark, whatever the ray count:
    // the bound there is 0.85.
    EXPECT_GE(fig16_ncc(cam, lenses, z, diffraction_mm), std::abs(z) <= 3 ? 0.95 : 0.85)
        << "z = " << z << " (measured 0.980-0.992 within 3 mm, 0.874-0.894 beyond)";
    // The weights through MART's sensor blur model (MartSettings::sensor_blur_sigma_mm) of the
    // same sigma, at every depth.
    EXPECT_GE(fig16_ncc(cam, lenses, z, diffraction_mm, diffraction_mm), 0.98)
        << "z = " << z << " (measured 0.992-0.999)";
  }
}

}  // namespace
}  // namespace plenopiv::recon

namespace plenopiv::recon {
namespace {

// Fig 21 in small: single particles at several depths, ray traced by core/sim (diffraction
// jitter 5.2 um, its default; 10^5 rays each so Monte Carlo noise stays below the fit's
// resolution: at 4 000 rays a particle can go unfound), reconstructed (5 iterations, mu = 0.5)
// and located by the Gaussian fit; lateral and depth errors in voxels.
TEST(MartFig21, SingleRayTracedParticlesAreFoundWhereTheyAre) {
  const auto cam = small_camera();
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  Grid3 g;
  g.shape = {24, 24, 64};
  g.spacing_mm = {0.125, 0.125, 0.125};
  g.origin_mm = {-1.4375, -1.4375, -3.9375};  // +-1.5 mm laterally, -4..4 mm in depth
  const WeightingOperator op(cam, lenses, g, calib::geometric_white_image(cam, lenses));
  double worst_lateral = 0, worst_depth = 0;
  for (double z : {-3.0, -1.5, 1.0, 2.5, 3.5}) {
    const std::array<double, 3> p{0.21, -0.13, z};
    sim::RenderOptions ro;
    ro.rays_per_particle = 100000;
    const ImageF image = sim::render(cam, lenses, std::vector<sim::Point3>{p}, ro, 21).rays;
    MartSettings s;
    s.dark_weight_cutoff = 0.9;
    const MartResult r = reconstruct(op, image, s);
    const auto fit = fit_particle(r.volume, p, {3, 3, 15});
    ASSERT_TRUE(fit) << "z = " << z;
    const double ex = (fit->position_mm[0] - p[0]) / 0.125, ey = (fit->position_mm[1] - p[1]) / 0.125;
    const double ez = (fit->position_mm[2] - p[2]) / 0.125;
    std::cout << "measured: single particle z = " << z << " mm: error x " << ex << " y " << ey << " z " << ez
              << " voxels, active " << r.skipped.voxels_active << "\n";
    worst_lateral = std::max({worst_lateral, std::abs(ex), std::abs(ey)});
    worst_depth = std::max(worst_depth, std::abs(ez));
  }
  // Lateral: the fit lands on the nearest voxel centre (the particle is 0.18 and 0.46 voxel from
  // it); depth: worst next to the focal plane (the ambiguity fig 21 shows too).
  EXPECT_LT(worst_lateral, 0.75) << "measured 0.46 (seed 21)";
  EXPECT_LT(worst_depth, 4.0) << "measured 2.5 at z = 1 mm (seed 21)";
}

}  // namespace
}  // namespace plenopiv::recon

namespace plenopiv::recon {
namespace {

TEST(MartSensorBlur, SpreadsAPixelAsAGaussianOfTheSigmaInPixels) {
  const auto cam = small_camera();
  const WeightingOperator op = make_operator(cam, centred_grid(4, 2, 0.5, 0.0));
  std::vector<float> image(op.pixel_count(), 0.f);
  const std::size_t centre = 400 * std::size_t(op.image_width()) + 300;
  image[centre] = 1000.f;
  apply_sensor_blur(op, 0.0052, image);  // 0.0052 / 0.0074 = 0.703 px
  double total = 0;
  for (float v : image) total += v;
  EXPECT_NEAR(total, 1000.0, 1e-3);  // far from the edges no light is lost
  const double sigma_px = 0.0052 / 0.0074;
  EXPECT_NEAR(image[centre + 1] / image[centre], std::exp(-0.5 / (sigma_px * sigma_px)), 0.01);
  EXPECT_NEAR(image[centre + std::size_t(op.image_width())] / image[centre], std::exp(-0.5 / (sigma_px * sigma_px)),
              0.01);
  std::vector<float> untouched(op.pixel_count(), 2.f);
  apply_sensor_blur(op, 0.0, untouched);
  EXPECT_EQ(untouched[centre], 2.f);
  EXPECT_THROW(apply_sensor_blur(op, -1.0, untouched), InputError);
  EXPECT_THROW(apply_sensor_blur(op, 0.0052, std::span<float>(untouched).first(100)), InputError);
}

// Sensor blur. core/sim's diffraction (sigma 5.2 um at the sensor, 0.7 px) widens the spot behind
// each lens; sec 5.2's weights match a wider spot best with a voxel nearer the focal plane, and
// particles come out compressed toward it. MART with the blur modelled (B W) takes part of that
// back. Small camera, one particle at a time at 8 depths (10^5 rays, seed 5), a 9 x 9 x 81 voxel
// box of 0.1 mm around it, 20 accelerated iterations at mu 1, depth from the moments; the slope of
// the signed depth error against depth, per cent.
TEST(MartSensorBlur, TakesBackPartOfTheDiffractionDepthCompression) {
  const auto cam = small_camera();
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  const ImageF white = calib::geometric_white_image(cam, lenses);
  const std::vector<double> depths{-8.0, -5.0, -3.0, -1.5, 1.5, 3.0, 5.0, 8.0};
  std::vector<ImageF> images;
  for (double z : depths) {
    sim::RenderOptions ro;
    ro.rays_per_particle = 100000;
    images.push_back(sim::render(cam, lenses, std::vector<sim::Point3>{{0.53, -0.41, z}}, ro, 5).rays);
  }
  auto slope_percent = [&](double blur_mm) {
    double sz = 0, sd = 0, szz = 0, szd = 0;
    for (std::size_t k = 0; k < depths.size(); ++k) {
      const sim::Point3 p{0.53, -0.41, depths[k]};
      Grid3 g;
      g.shape = {9, 9, 81};
      g.spacing_mm = {0.1, 0.1, 0.1};
      g.origin_mm = {p[0] - 0.363, p[1] - 0.421, p[2] - 3.987};  // the particle off the voxel centres
      const WeightingOperator op(cam, lenses, g, white);
      MartSettings s;
      s.iterations = 20;
      s.mu = 1.0;
      s.accelerate = true;
      s.sensor_blur_sigma_mm = blur_mm;
      const auto fit = fit_particle_moments(reconstruct(op, images[k], s).volume, p, {3, 3, 30});
      if (!fit) {
        ADD_FAILURE() << "particle at z = " << p[2] << " not found, blur " << blur_mm;
        continue;
      }
      const double d = fit->position_mm[2] - p[2];
      sz += p[2];
      sd += d;
      szz += p[2] * p[2];
      szd += p[2] * d;
    }
    const double n = double(depths.size());
    return 100 * (n * szd - sz * sd) / (n * szz - sz * sz);
  };
  const double without = slope_percent(0.0), with = slope_percent(sim::RenderOptions{}.diffraction_sigma_mm);
  std::cout << "measured: depth error slope " << without << " % without the blur model, " << with << " % with it\n";
  // The blur model takes part of the depth error's slope away.
  EXPECT_LT(without, -2.5) << "measured -3.04 %";
  EXPECT_GT(with, without + 0.8) << "measured -1.85 %";
  EXPECT_LT(std::abs(with), 2.3);
}

}  // namespace
}  // namespace plenopiv::recon
